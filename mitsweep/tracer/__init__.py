"""mitsweep.tracer (see DESIGN.md)."""
