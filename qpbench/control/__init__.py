"""The paper's controller: QP terms, the per-tick build (eq. 11) and the adaptive law (section 4.4)."""
