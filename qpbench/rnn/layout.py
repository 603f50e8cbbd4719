"""The parameter block ``prm`` the network's kernels read (inputs) and fill (outputs), and their codes.

Index constants of one float64 array per call (:func:`qpbench.rnn.step_bound.make_params`
builds it), shared by the numpy integrator and the compiled kernels.
"""

from __future__ import annotations

#: Integration methods.
METHODS = ("euler", "semi-implicit")

#: Squarings in the trace-power bound of ``sigma_max(C)^2``.
_SQUARINGS = 5

#: Layout of the parameter block ``prm`` the kernels read (inputs) and fill (outputs).
PMIN, PMAX, SEMI, R_TOTAL, SUBSTEPS, SAFETY, MAX_STEPS, TOL, L1_CLIP = range(9)
PRIMAL, DUAL, COMPL, OBJ, RATIO, RATIO_MAX, SIG2 = range(9, 16)
#: Inputs of the per-tick kernel (:func:`online_kernel`): the residual bounds of
#: status ``optimal`` and the equality count of the state's split (-1: not checked);
#: and one more output of every kernel: the last call's step count or code (NaN: none yet).
OK_PRIMAL, OK_DUAL, STATE_ME, STEPS = range(16, 20)
#: Inputs of a fixed step: the ratio ``r = h / eps`` of one step the setting
#: asks for (0: none; then ``SUBSTEPS`` or the bound decides the count) and
#: whether to clamp a forced step to the stability bound (1) or not (0);
#: output: the step count the setting asked for (0 when the bound chose it).
R_STEP, CLAMP, NOMINAL = range(20, 23)
#: Output: what a fixed-duration call did against its setting (:data:`NOTES`).
NOTE = 23
PRM_SIZE = 24

#: ``prm[NOTE]`` values: nothing to say; the step was clamped to the bound (more
#: steps); no step is proven stable (``P`` not positive definite: the steps ran
#: as set); the steps the bound needs exceed ``MAX_STEPS`` (capped there: the
#: step stays above the bound).
NOTE_NONE, NOTE_CLAMPED, NOTE_UNPROVEN, NOTE_CAPPED = 0, 1, 2, 3

#: Kernel return codes besides a step count.
NO_STABLE_STEP = -1
SHAPE_MISMATCH = -2
#: Per-tick kernel only: the state is no longer finite.
DIVERGED = -3
