"""The CLI's user-error contract, checked the same way by every test that needs it."""

from __future__ import annotations

import json
import warnings

from mitsweep.cli.main import main


def refused(capsys, argv) -> str:
    """Run ``mitsweep ARGV`` and assert a clean refusal; return the error line.

    A clean refusal: exit status 2, exactly one line on stderr starting with
    ``mitsweep: error:``, no traceback, no Python warning, nothing on stdout; with
    ``--json``, stdout holds one JSON object ``{"error", "command", "exit_status"}``
    whose error is the stderr line's message.
    """
    capsys.readouterr()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse's own errors
            rc = exc.code
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, f"exit status {rc}; stderr: {err!r}"
    assert len(lines) == 1, lines
    assert "error:" in lines[0] and "Traceback" not in err
    assert not caught, [str(w.message) for w in caught]
    if "--json" in [str(a) for a in argv]:
        obj = json.loads(out)  # one object and nothing else
        assert obj == {"error": lines[0].split("error: ", 1)[1], "command": obj["command"],
                       "exit_status": 2}, obj
        assert obj["command"] in [str(a) for a in argv], obj
    else:
        assert out == ""
    return lines[0]


def run_main(capsys, *args) -> tuple[int, str, str]:
    """Run ``mitsweep ARGS`` in this process: (exit status, stdout, stderr), as
    :func:`conftest.run_cli` returns them from a subprocess (which pays ~1 s of Python
    and Mitsuba start-up per call: kept for what only a new process shows, such as the
    exit status of ``python -m mitsweep`` itself or a clean environment)."""
    capsys.readouterr()
    try:
        rc = main([str(a) for a in args])
    except SystemExit as exc:  # argparse's own errors
        rc = exc.code if isinstance(exc.code, int) else 2
    out, err = capsys.readouterr()
    return rc, out, err
