"""Running the ``jwarp`` CLI in-process in tests: :func:`run` and :func:`one_line_error`."""

from jwarp.cli import main


def run(capsys, argv):
    """``main(argv)`` (every item as a string); returns (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(capsys, argv, option):
    """Run argv; assert exit 2, nothing on stdout and a last stderr line
    ``jwarp: error: <option>: ...`` (argparse's own errors print the usage before it);
    return that line."""
    code, out, err = run(capsys, argv)
    lines = [ln for ln in err.splitlines() if not ln.startswith("Warp CUDA warning")]
    assert code == 2, (code, out, err)
    assert out == ""
    if len(lines) > 1:
        assert lines[0].startswith("usage:"), err
    assert lines[-1].startswith(f"jwarp: error: {option}: "), lines[-1]
    return lines[-1]


def q_text(q) -> str:
    """Joint values as the CLI's comma-separated ``--start``/``--goal`` text."""
    return ",".join(str(v) for v in q)
