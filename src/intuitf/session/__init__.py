"""intuitf.session."""
