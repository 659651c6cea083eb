"""The time-domain engine, the virtual laboratory and the thesis reproductions."""
