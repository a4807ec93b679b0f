"""Evaluation: metrics, the workspace and obstacle benchmarks, figures, the paper reproduction."""
