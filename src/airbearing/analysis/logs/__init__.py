"""airbearing.analysis.logs: a lab's own log files turned into logs (the import map)."""
