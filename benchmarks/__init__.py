"""The bench harness behind ``routefuse bench`` (a source checkout's tool, not installed)."""
