"""The closed loop's engines and the one model of a run they share."""
