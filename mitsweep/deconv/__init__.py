"""mitsweep.deconv (see DESIGN.md)."""
