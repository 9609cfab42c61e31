"""mitsweep: extended-depth-of-field catadioptric imaging with focal sweep.

Implements and extends Yokoya & Nayar, "Extended Depth of Field Catadioptric Imaging
Using Focal Sweep": optics and the optimal sweep range (:mod:`mitsweep.optics`), a
Dr.Jit point-source tracer for IPSFs (:mod:`mitsweep.tracer`), Mitsuba 3 rendering with
a moving-sensor thin lens (:mod:`mitsweep.render`), deconvolution
(:mod:`mitsweep.deconv`) and rig control (:mod:`mitsweep.rig`).

Start with :mod:`mitsweep.workflows`: each ``mitsweep`` command's job as one documented
function (``restore_photo``, ``calibrate_camera``, ``trace_ipsf``, ``build_dataset``,
``render_exr``, ...) that returns its result with its provenance.
"""

__version__ = "0.1.0"
