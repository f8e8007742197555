"""intuitf.render."""
