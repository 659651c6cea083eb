"""Circuit descriptions, netlists, units and expressions, frequency-dependent ladders, symbolic forms."""
