"""intuitf.evaluator."""
