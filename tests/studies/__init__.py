"""The thesis's studies and the real-data fits."""
