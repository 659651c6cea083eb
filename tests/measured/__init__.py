"""Measured-data readers and writers on real and written files."""
