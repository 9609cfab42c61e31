"""Bank files: optics and fingerprint round-trip, every missing field named, old formats."""

import json
import warnings

import numpy as np
import pytest

from mitsweep.config import DEFAULT_SETUP, setup_to_dict
from mitsweep.deconv.synthetic import synthetic_radial_bank
from mitsweep.io.bank import (BANK_FORMAT, BankError, IPSFBank, load_bank, optics_fingerprint,
                              optics_sections, save_bank)

OPTICS = optics_sections(setup_to_dict(DEFAULT_SETUP),
                         {"kind": "linear", "start_mm": 363.1, "end_mm": 363.8})


def traced_like(**changes) -> IPSFBank:
    """A small radial bank that claims DEFAULT_SETUP's optics."""
    base = synthetic_radial_bank((64, 64), size=9, n_radii=3)
    kw = dict(kernels=base.kernels, points_uv=base.points_uv, depths=base.depths,
              pixel_pitch=base.pixel_pitch, reference_sensor_distance=363.4, kind="radial",
              radii=base.radii, metadata={"seed": 1}, optics=OPTICS)
    kw.update(changes)
    return IPSFBank(**kw)


def arrays_of(path):
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def rewrite(path, arrays):
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def edit_header(path, edit):
    arrays = arrays_of(path)
    header = json.loads(str(arrays["header"][()]))
    edit(header)
    arrays["header"] = np.array(json.dumps(header))
    rewrite(path, arrays)


def test_optics_and_fingerprint_round_trip(tmp_path):
    p = save_bank(tmp_path / "b.npz", traced_like())
    header = json.loads(str(arrays_of(p)["header"][()]))   # a readable 0-d string array
    assert header["format"] == BANK_FORMAT
    assert header["optics_sha256"] == optics_fingerprint(OPTICS)
    bank = load_bank(p)
    assert bank.fingerprinted and bank.optics == OPTICS
    assert bank.optics["sweep"]["depth_max"] == 10000.0


def test_fingerprint_ignores_order_and_tuple_spelling():
    shuffled = {k: dict(reversed(list(v.items()))) for k, v in reversed(list(OPTICS.items()))}
    assert optics_fingerprint(shuffled) == optics_fingerprint(OPTICS)
    other = {**OPTICS, "lens": {**OPTICS["lens"], "f_number": 4.0}}
    assert optics_fingerprint(other) != optics_fingerprint(OPTICS)
    inf = optics_sections({"sweep": {"depth_max": float("inf")}})
    assert inf == {"sweep": {"depth_max": "inf"}}          # canonical JSON has no Infinity


def test_synthetic_banks_claim_no_optics(tmp_path):
    bank = load_bank(save_bank(tmp_path / "s.npz", synthetic_radial_bank((32, 32), size=5)))
    assert bank.optics is None and bank.fingerprinted and bank.metadata["synthetic"]


@pytest.mark.parametrize("field,message", [
    ("kind", "the bank header lacks 'kind'"),
    ("pixel_pitch", "the bank header lacks 'pixel_pitch'"),
    ("reference_sensor_distance", "the bank header lacks 'reference_sensor_distance'"),
    ("optics_sha256", "lacks 'optics' and 'optics_sha256'"),
])
def test_a_missing_header_field_is_named(tmp_path, field, message):
    p = save_bank(tmp_path / "b.npz", traced_like())
    edit_header(p, lambda h: h.pop(field))
    with pytest.raises(BankError, match=message):
        load_bank(p)


@pytest.mark.parametrize("name", ["kernels", "points_uv", "depths_mm"])
def test_a_missing_array_is_named(tmp_path, name):
    p = save_bank(tmp_path / "b.npz", traced_like())
    arrays = arrays_of(p)
    del arrays[name]
    rewrite(p, arrays)
    with pytest.raises(BankError, match=f"the bank lacks the '{name}' array"):
        load_bank(p)


@pytest.mark.parametrize("key,value,message", [
    ("pixel_pitch", "0.018", "pixel_pitch must be a positive number"),
    ("pixel_pitch", -1.0, "pixel_pitch must be a positive number"),
    ("reference_sensor_distance", None, "reference_sensor_distance must be a positive"),
    ("kind", "spiral", "kind must be 'radial' or 'grid'"),
    ("grid_shape", [0, 3], "grid_shape must be"),
    ("metadata", [1, 2], "metadata must be a JSON object"),
])
def test_bad_header_values_are_refused(tmp_path, key, value, message):
    p = save_bank(tmp_path / "b.npz", traced_like())
    edit_header(p, lambda h: h.__setitem__(key, value))
    with pytest.raises(BankError, match=message):
        load_bank(p)


def test_edited_optics_break_the_fingerprint(tmp_path):
    p = save_bank(tmp_path / "b.npz", traced_like())
    edit_header(p, lambda h: h["optics"]["mirror"].__setitem__("radius", 30.0))
    with pytest.raises(BankError, match="do not match their fingerprint"):
        load_bank(p)


def test_empty_kernels_are_refused():
    base = traced_like()
    with pytest.raises(BankError, match="the bank holds no kernels"):
        traced_like(kernels=base.kernels[:0], depths=base.depths[:0])


def test_format_1_banks_load_unfingerprinted_and_cannot_be_resaved(tmp_path):
    p = save_bank(tmp_path / "b.npz", traced_like())
    arrays = arrays_of(p)
    header = json.loads(str(arrays["header"][()]))
    for key in ("optics", "optics_sha256"):
        header.pop(key)
    header["format"] = "mitsweep-ipsf-bank/1"
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)  # as /1 stored it
    rewrite(p, arrays)
    old = load_bank(p)
    assert not old.fingerprinted and old.optics is None
    np.testing.assert_array_equal(old.kernels, traced_like().kernels)
    with pytest.raises(BankError, match="predates optics fingerprints"):
        save_bank(tmp_path / "again.npz", old)


@pytest.mark.parametrize("data", [b"PK\x03\x04 garbage", b"PK\x03\x04" + bytes(200)])
def test_a_corrupt_archive_is_refused_without_leaking_the_file(tmp_path, data):
    p = tmp_path / "b.npz"
    p.write_bytes(data)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(BankError, match="not an IPSF bank"):
            load_bank(p)
        import gc
        gc.collect()                     # an unclosed handle warns when collected
    assert not [w for w in caught if issubclass(w.category, ResourceWarning)]
