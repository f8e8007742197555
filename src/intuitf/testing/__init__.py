"""intuitf.testing."""
