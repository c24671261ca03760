"""Reporting: self-contained HTML, figures, every demo section and the demo."""
