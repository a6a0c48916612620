"""Running `ovon` in this process and checking that it refused in one line (the bad-input tests share these)."""

from __future__ import annotations

import warnings

from ovon.cli.main import main as ovon


def run(argv: list[str], capsys) -> tuple[int, str, list[str]]:
    """`ovon argv` in this process: exit code, stdout, and the lines of stderr that are not warnings."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            rc = ovon(argv)
        except SystemExit as e:  # argparse
            rc = int(e.code or 0)
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "internal error" not in err, err
    return rc, out, [ln for ln in err.strip().splitlines() if ln.strip() and not ln.startswith("ovon: warning:")]


def one_line(rc: int, errors: list[str], *needles: str) -> str:
    """The one `ovon: error:` line (exit 2) holding every needle and a fix."""
    assert rc == 2 and len(errors) == 1 and errors[0].startswith("ovon: error:"), (rc, errors)
    for n in needles:
        assert n in errors[0], (n, errors[0])
    assert "fix:" in errors[0], errors[0]
    return errors[0]


def refused(rc: int, errors: list[str], *needles: str) -> str:
    """Either kind of one-line refusal: ovon's own (`one_line`), or argparse's for a malformed command line
    (`ovon CMD: error: ... (see ovon CMD --help)`), whose fix is the help it names."""
    if not (errors and errors[0].rstrip().endswith("--help)")):
        return one_line(rc, errors, *needles)
    assert rc == 2 and len(errors) == 1 and errors[0].startswith("ovon") and ": error:" in errors[0], (rc, errors)
    for n in needles:
        assert n in errors[0], (n, errors[0])
    return errors[0]
