"""airbearing.io."""
