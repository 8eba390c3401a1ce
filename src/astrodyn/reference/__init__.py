"""Independent high-precision references (mpmath, 30-50 digits).

These implementations share no code with the numeric core; tests and benchmarks
compare the core against them.  Slow by design: use on samples only.
"""
