"""Figures, pressure-map renders and HTML reports."""
