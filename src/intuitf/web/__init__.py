"""intuitf.web."""
