"""Discrepancy: replay a log through the model, localise the gap, name the missing effects."""
