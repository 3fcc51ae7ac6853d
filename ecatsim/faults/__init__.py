"""Fault injection: faults as data (spec), patches to replies (wire), and the engine that
triggers them and acts on the segment (engine)."""
