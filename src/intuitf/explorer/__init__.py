"""intuitf.explorer."""
