r"""Poisson–Gaussian sensor noise from scene light (Cossairt, Gupta & Nayar 2013).

Image values are *relative exposure*: 1.0 is the image of a Lambertian surface of
reflectance ``reflectance`` lit by ``illuminance_lux`` (a clean render scaled so that
the scene's mean reflectance maps to 1 fits this directly). A pixel then collects, on
average,

.. math:: J = 10^{15}\,\frac{t\, I\, R\, q\, \Delta^2}{N^2}\quad\text{photo-electrons}

(paper [5]_, Sec. V: :math:`I` illuminance in lux, :math:`R` reflectance, :math:`t`
exposure in s, :math:`N` the f-number, :math:`q` the quantum efficiency, :math:`\Delta`
the pixel size in metres; :math:`10^{15}` ≈ photons per lux-second-m² at 555 nm over
the 4 of the Lambertian image irradiance :math:`I R / 4 N^2`). The recorded value is

.. math:: e \sim \mathrm{Poisson}(x J) + \mathcal N(0, \sigma_r^2), \qquad
          \mathrm{DN} = \mathrm{round}\big(g\, e + \mathcal N(0, \sigma_{adc}^2)\big)

with the analogue gain :math:`g` = ``gain_dn_per_e_at_iso100`` × ISO/100 (DN per
electron), ``read_noise_e`` before the gain and ``adc_noise_dn`` after it (so a higher
ISO lowers the input-referred noise, as in real sensors), clipped to the ADC range
[0, 2^bits − 1] and to the full well: a physical saturation, which is stated, not
silent (``saturated_fraction`` in :meth:`SensorNoise.apply`'s info). The output is
converted back to relative exposure, DN / (g J), so a noisy image is an unbiased
estimate of the clean one below saturation.

References
----------
.. [5] O. Cossairt, M. Gupta and S. K. Nayar, "When does computational imaging improve
   performance?", IEEE Trans. Image Process. 22(2), 447–458, 2013.
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..deprecation import renamed_fields, renamed_keywords

__all__ = ["SensorNoise", "PHOTONS_PER_LUX_S_M2", "paper_fig10_settings"]

logger = logging.getLogger(__name__)

#: Cossairt et al.'s constant: photo-electron count J = 1e15 · t I R q Δ² / N².
PHOTONS_PER_LUX_S_M2 = 1e15


def _check(name, value, lo=0.0, lo_open=True, hi=math.inf):
    v = float(value)
    ok = (v > lo if lo_open else v >= lo) and v <= hi and math.isfinite(v)
    if not ok:
        rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
        raise ValueError(f"noise.{name} must be a finite number in {rng}, got {value!r}")
    return v


#: Illuminances (lux) the command line accepts for a noise model: from a moonless night
#: sky to beyond direct sunlight. Outside it the model's signal underflows or overflows
#: (1e-300 lux: no electron; 1e300 lux: inf), and the NSR a design or dataset uses with it.
ILLUMINANCE_RANGE_LUX = (1e-4, 1e6)


@renamed_fields(pixel_size_mm="pixel_pitch")
@dataclass(frozen=True, kw_only=True)
class SensorNoise:
    """Sensor and exposure settings that fix the noise of an image.

    Parameters
    ----------
    illuminance_lux : float
        Scene illuminance, lux (the paper's Fig. 10: about 50).
    exposure_s : float
        Exposure time, s.
    f_number : float
        Working f-number N of the lens.
    pixel_pitch : float
        Pixel pitch, mm (``setup.sensor.pixel_pitch``). The former keyword
        ``pixel_size_mm`` is still accepted, with a :class:`DeprecationWarning`.
    reflectance : float
        Mean scene reflectance R that relative exposure 1.0 stands for.
    quantum_efficiency : float
        Photo-electrons per photon, q.
    read_noise_e : float
        Read noise before the gain, electrons rms.
    iso : float
        ISO setting; the gain is ``gain_dn_per_e_at_iso100 * iso / 100``.
    gain_dn_per_e_at_iso100 : float
        Conversion gain at ISO 100, DN per electron.
    adc_noise_dn : float
        Noise after the gain (ADC, downstream electronics), DN rms.
    full_well_e : float
        Full-well capacity, electrons.
    bits : int
        ADC bit depth.

    Defaults describe a full-frame DSLR of the paper's era (Canon EOS 5D Mark II class:
    6.4 µm pixels, 14 bit, ~60 000 e⁻ full well, so 0.27 DN/e⁻ at ISO 100, 3 e⁻ read
    noise, 2 DN ADC noise). Check: at ISO 100 the ISO 12232 saturation exposure is
    78/100 = 0.78 lux·s; at 50 lux, F2.8, 0.6 s a reflectance-ρ surface gives
    ρ · 50 / (4 · 2.8²) · 0.6 = 0.96 ρ lux·s, saturating at ρ ≈ 0.8. This model
    (R = 0.5, q = 0.5) saturates at 1.53 · 0.5 ≈ 0.77.
    """

    illuminance_lux: float
    exposure_s: float
    f_number: float
    pixel_pitch: float
    reflectance: float = 0.5
    quantum_efficiency: float = 0.5
    read_noise_e: float = 3.0
    iso: float = 100.0
    gain_dn_per_e_at_iso100: float = 0.27
    adc_noise_dn: float = 2.0
    full_well_e: float = 60000.0
    bits: int = 14

    def __post_init__(self) -> None:
        _check("illuminance_lux", self.illuminance_lux, lo=0.0, lo_open=False)
        _check("exposure_s", self.exposure_s)
        _check("f_number", self.f_number)
        _check("pixel_pitch", self.pixel_pitch)
        _check("reflectance", self.reflectance, hi=1.0)
        _check("quantum_efficiency", self.quantum_efficiency, hi=1.0)
        _check("read_noise_e", self.read_noise_e, lo_open=False)
        _check("iso", self.iso)
        _check("gain_dn_per_e_at_iso100", self.gain_dn_per_e_at_iso100)
        _check("adc_noise_dn", self.adc_noise_dn, lo_open=False)
        _check("full_well_e", self.full_well_e)
        if not (isinstance(self.bits, int) and 1 <= self.bits <= 32):
            raise ValueError(f"noise.bits must be an integer in [1, 32], got {self.bits!r}")

    # -- the model -----------------------------------------------------------------
    @property
    def electrons_per_unit(self) -> float:
        """J: mean photo-electrons for relative exposure 1.0."""
        delta_m = self.pixel_pitch * 1e-3
        return (PHOTONS_PER_LUX_S_M2 * self.exposure_s * self.illuminance_lux
                * self.reflectance * self.quantum_efficiency * delta_m ** 2
                / self.f_number ** 2)

    @property
    def gain(self) -> float:
        """Conversion gain g, DN per electron."""
        return self.gain_dn_per_e_at_iso100 * self.iso / 100.0

    @property
    def saturation(self) -> float:
        """Relative exposure at which the pixel saturates (full well or ADC range)."""
        J = self.electrons_per_unit
        if J == 0:
            return math.inf
        return min(self.full_well_e, (2 ** self.bits - 1) / self.gain) / J

    def variance(self, x: ArrayLike) -> np.ndarray:
        """Noise variance of relative exposure ``x`` (no saturation), in x units².

        ``(x J + σ_r² + (σ_adc² + 1/12) / g²) / J²``: shot, read, ADC and quantisation.

        Parameters
        ----------
        x : float or array_like
            Relative exposure (1.0: the reference surface); negative values count as 0.

        Returns
        -------
        ndarray
            The variance, the shape of ``x``; inf everywhere when no light reaches the
            sensor.
        """
        J = self.electrons_per_unit
        if J == 0:
            return np.full(np.shape(x), math.inf)
        g = self.gain
        e_var = np.clip(np.asarray(x, dtype=np.float64), 0, None) * J + self.read_noise_e ** 2 \
            + (self.adc_noise_dn ** 2 + 1.0 / 12.0) / g ** 2
        return e_var / J ** 2

    def snr(self, x: float = 1.0) -> float:
        """Signal-to-noise ratio (linear) of a pixel at relative exposure ``x``.

        Parameters
        ----------
        x : float
            Relative exposure (default 1.0, the reference surface).
        """
        return float(x / math.sqrt(float(self.variance(x))))

    def nsr(self, mean_level: float = 0.5, signal_std: float | None = None) -> float:
        """Constant Wiener noise-to-signal power ratio this noise implies.

        ``variance(mean_level) / signal_std²``; ``signal_std`` defaults to
        ``mean_level``, the rms contrast of natural images being about their mean
        (pass the measured standard deviation of a clean image when known).

        Parameters
        ----------
        mean_level : float
            Mean relative exposure of the image (default 0.5).
        signal_std : float, optional
            Standard deviation of the clean image, relative exposure (> 0; default
            ``mean_level``).
        """
        s = mean_level if signal_std is None else signal_std
        if not s > 0:
            raise ValueError(f"signal_std must be > 0, got {s!r}")
        return float(self.variance(mean_level)) / float(s) ** 2

    def apply(self, image: np.ndarray, rng: np.random.Generator | int | None = None,
              *, info: dict | None = None) -> np.ndarray:
        """A noisy copy of ``image`` (relative exposure, any shape; float32 stays float32).

        Negative pixels (filter ringing, round-off) receive no light: they read as 0.

        Parameters
        ----------
        rng : numpy.random.Generator or int
            Random source (an int seeds ``numpy.random.default_rng``). Required for
            reproducibility: ``None`` is refused.
        info : dict, optional
            Filled with ``saturated_fraction``, ``electrons_per_unit``, ``gain``.

        Returns
        -------
        ndarray
            ``DN / (g J)``: saturated pixels read about ``saturation``; black stays ≈ 0 ± read
            noise (negative values are kept: no clipping at 0 beyond the ADC's).
        """
        if rng is None:
            raise ValueError("noise needs a seed or numpy Generator (reproducibility)")
        gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(int(rng))
        x = np.asarray(image)
        out_dt = np.float32 if x.dtype == np.float32 else np.float64
        xf = x.astype(np.float64)
        if not np.all(np.isfinite(xf)):
            raise ValueError("image holds NaN or inf values")
        if np.any(xf < 0):
            # no light is negative: negatives come from reconstruction-filter ringing
            # (Mitchell, Lanczos) or FFT round-off; they expose the sensor to nothing
            logger.debug("%d negative pixels treated as 0", int(np.sum(xf < 0)))
            xf = np.clip(xf, 0, None)
        J = self.electrons_per_unit
        if J == 0:
            raise ValueError("no light (illuminance 0): the image would be undefined")
        g = self.gain
        electrons = gen.poisson(xf * J).astype(np.float64)
        full = electrons >= self.full_well_e
        electrons = np.minimum(electrons, self.full_well_e)
        electrons += gen.normal(0.0, self.read_noise_e, size=xf.shape)
        dn = g * electrons + gen.normal(0.0, self.adc_noise_dn, size=xf.shape)
        dn_max = 2 ** self.bits - 1
        # the ADC has an offset in real cameras; we keep the signed value below 0 so that
        # dark noise stays unbiased, and clip only at the top of the range
        dn = np.minimum(np.round(dn), dn_max)
        sat = float(np.mean(full | (dn >= dn_max)))
        if info is not None:
            info.update(saturated_fraction=sat, electrons_per_unit=J, gain=g)
        if sat > 0:
            logger.info("%.3g %% of pixels saturated", 100 * sat)
        return (dn / (g * J)).astype(out_dt)

    def as_dict(self) -> dict:
        """Provenance; the pitch under its JSON key ``pixel_size_mm``, as before."""
        return {("pixel_size_mm" if k == "pixel_pitch" else k): v
                for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> SensorNoise:
        """The model of its :meth:`as_dict` (provenance back to a model).

        Parameters
        ----------
        d : dict
            An :meth:`as_dict` output: the fields by name, the pitch under
            ``pixel_size_mm`` (``pixel_pitch`` is read too).
        """
        return cls(**{("pixel_pitch" if k == "pixel_size_mm" else k): v for k, v in d.items()})


@renamed_keywords(pixel_size_mm="pixel_pitch")
def paper_fig10_settings(pixel_pitch: float, illuminance_lux: float = 50.0) -> dict:
    """The paper's Fig. 10 comparison: focal sweep F2.8, 0.6 s, ISO 100 against a
    stopped-down F11, 0.6 s, ISO 1600 exposure.

    Parameters
    ----------
    pixel_pitch : float
        Pixel pitch of the sensor, mm (the paper's Fig. 10: 0.0064). The former keyword
        ``pixel_size_mm`` is still accepted, with a :class:`DeprecationWarning`.
    illuminance_lux : float
        Scene illuminance of both exposures, lux (default 50, the paper's).

    Returns
    -------
    dict
        ``{"sweep": SensorNoise, "stopped": SensorNoise}``.
    """
    return {"sweep": SensorNoise(f_number=2.8, iso=100.0, illuminance_lux=illuminance_lux,
                                 exposure_s=0.6, pixel_pitch=pixel_pitch),
            "stopped": SensorNoise(f_number=11.0, iso=1600.0, illuminance_lux=illuminance_lux,
                                   exposure_s=0.6, pixel_pitch=pixel_pitch)}
