"""Verification campaigns, metrics and regression checks (docs/references.md#the-thesiss-figures, docs/method.md#7-comparison-metrics)."""
