"""``mitsweep dataset``'s scale-out options: a bad value is one line, exit status 2,
before anything is created; restoration methods come from ``deconv.METHODS``."""

import pytest

from mitsweep.cli.main import main
from mitsweep.pipeline import DatasetError, DatasetOptions, edof_name, item_names
from test_io_write_errors import tiny_setup_toml


@pytest.mark.parametrize("args,message", [
    (["--shard", "3/2"], "argument --shard: must be K/N with 1 <= K <= N <= 10000, got 3/2"),
    (["--shard", "0/4"], "argument --shard: must be K/N with 1 <= K <= N"),
    (["--shard", "two"], "argument --shard: must be K/N with 1 <= K <= N <= 10000 (e.g. 1/4), "
                         "got 'two'"),
    (["--scheduler", "localhost:8786"], "argument --scheduler: must be a Dask scheduler "
                                        "address tcp://HOST:PORT (port 1-65535), got "
                                        "'localhost:8786'"),
    (["--scheduler", "tcp://host:99999"], "argument --scheduler: must be a Dask scheduler"),
    (["--scheduler", "http://host:8786"], "argument --scheduler: must be a Dask scheduler"),
    (["--scheduler", "tcp://127.0.0.1:8786", "--executor", "process"],
     "mitsweep: error: --scheduler: needs --executor dask (or no --executor), got "
     "--executor process"),
    (["--executor", "ray"], "argument --executor: invalid choice: 'ray'"),
    (["--methods", "wiener,nope"], "mitsweep: error: --methods: unknown restoration method "
                                   "'nope'; allowed: wiener"),
    (["--methods", "wiener,wiener"], "mitsweep: error: --methods: each method at most once"),
    (["--methods", "wiener,"], "argument --methods: expected method names separated by "
                               "commas"),
    (["--retries", "-1"], "argument --retries: must be >= 0, got -1"),
])
def test_bad_scale_out_options_are_one_line(tmp_path, capsys, args, message):
    setup = tiny_setup_toml(tmp_path)
    out = tmp_path / "new" / "ds"
    try:
        rc = main(["dataset", str(setup), "--out", str(out), *args])
    except SystemExit as exc:  # argparse's own one-line errors
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert message in err
    assert not (tmp_path / "new").exists()


def test_methods_are_read_from_deconv_at_validation_time(monkeypatch):
    from mitsweep import deconv

    with pytest.raises(DatasetError, match="unknown restoration method 'later'"):
        DatasetOptions(methods=("wiener", "later"))
    monkeypatch.setattr(deconv, "METHODS", (*deconv.METHODS, "later"))
    opts = DatasetOptions(methods=("wiener", "later"), light_levels_lux=(50.0,))
    names = item_names(opts)
    # Wiener keeps the names the demo and the plots read; another method has its own.
    assert {"scene_000/edof.exr", "scene_000/edof_50lux.exr", "scene_000/edof_later.exr",
            "scene_000/edof_later_50lux.exr"} <= set(names)
    assert edof_name("wiener") == "edof" and edof_name("later", "_2lux") == "edof_later_2lux"


def test_unreachable_scheduler_is_one_line(tmp_path, capsys):
    setup = tiny_setup_toml(tmp_path)
    out = tmp_path / "ds"
    rc = main(["dataset", str(setup), "--out", str(out), "--scheduler", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("mitsweep: error: scheduler: cannot reach a Dask scheduler at "
                          "tcp://127.0.0.1:9 within 10 s")
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()
