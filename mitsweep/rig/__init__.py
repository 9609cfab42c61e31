"""mitsweep.rig (see DESIGN.md)."""
