"""airbearing.design."""
