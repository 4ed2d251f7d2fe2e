"""Benchmarks: run time against error of the lens-sampling methods (``time_error``) and
``--method auto`` against the fixed methods (``auto``)."""
