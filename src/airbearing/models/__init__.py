"""airbearing.models."""
