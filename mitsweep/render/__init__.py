"""mitsweep.render (see DESIGN.md)."""
