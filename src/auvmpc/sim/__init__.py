"""The closed loop, its log (time-major arrays), metrics and the run verdict."""
