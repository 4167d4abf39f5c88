"""Verification campaigns, metrics and regression checks (SPEC 7-8)."""
