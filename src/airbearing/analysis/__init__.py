"""airbearing.analysis."""
