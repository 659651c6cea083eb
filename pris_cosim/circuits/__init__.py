"""Circuit descriptions: elements, parameters and expressions, netlists, the PRIS arrangement, nodal analysis (MNA), frequency-dependent ladders."""
