"""The command line: every option a command accepts is read by that command, and --set reaches
a parameter, a constant input and a master key."""
from __future__ import annotations

import argparse
import inspect
import json
import re

import pytest

from tests.conftest import SCENARIOS


def _commands(parser, path=()):
    """(command path, parser) for every leaf subcommand."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield path, parser
        return
    for name, sub in subs[0].choices.items():
        yield from _commands(sub, path + (name,))


def _reads(source: str, dest: str) -> bool:
    """args.dest, or getattr(args, ...) with the name "dest" written in the same code (a loop
    over option names), or a master's declared option read by the loop over the declarations
    (cli._master_options_from)."""
    from crankfmu.masters import all_options
    declared = dest.startswith("master_") and dest[len("master_"):] in all_options()
    return re.search(rf"args\.{dest}\b", source) is not None or \
        ("getattr(args, " in source and f'"{dest}"' in source) or \
        (declared and 'getattr(args, f"master_{name}"' in source)


def test_every_option_is_used_by_its_command():
    """Walks the parsers: for each option of each command, its handler (with the shared helper
    load_with_options when the handler calls it, and run_command for the global options)
    reads it."""
    from crankfmu import cli
    parser = cli.build_parser()
    main_source = inspect.getsource(cli.run_command)
    for action in parser._actions:
        if action.dest not in ("help", "version", "command") and \
                not isinstance(action, argparse._SubParsersAction):
            assert _reads(main_source, action.dest), action.dest
    unused, seen = [], 0
    for path, sub in _commands(parser):
        func = sub.get_default("func")
        source = inspect.getsource(func)
        for helper in (cli.load_with_options, cli._master_options_from):
            if helper.__name__ in source:
                source += inspect.getsource(helper)
        for action in sub._actions:
            if action.dest in ("help",) or action.dest == argparse.SUPPRESS:
                continue
            seen += 1
            if not _reads(source, action.dest):
                unused.append(f"crankfmu {' '.join(path)} {action.option_strings or action.dest}")
    assert seen > 80 and unused == []


def test_run_options_meaning_nothing_elsewhere_are_gone():
    from crankfmu import cli
    parser = cli.build_parser()
    opts = {path[0]: {o for a in sub._actions for o in a.option_strings}
            for path, sub in _commands(parser) if len(path) == 1}
    for command in ("reference", "accuracy"):
        assert not opts[command] & {"--algorithm", "--extrapolation", "--log"}, command
    assert "--step" not in opts["accuracy"] and "--plot" not in opts["accuracy"]
    for command in ("run", "reference", "accuracy", "sweep", "export-ssp"):
        assert "--set" in opts[command] and "--stop-time" in opts[command]
    for command in ("run", "accuracy", "compare", "sweep", "export-ssp"):
        assert "--fmus" in opts[command]
    for command in ("compare", "sweep"):  # --out defaults to results/ as elsewhere
        sub = dict(_commands(parser))[(command,)]
        assert not [a for a in sub._actions if a.dest == "out" and a.required]


def test_set_on_the_command_line(tmp_path, fmu_dir, capsys):
    """A parameter, a constant input and a master key, through `crankfmu run --set`."""
    from crankfmu.cli import main
    out = tmp_path / "servo_press.csv"
    assert main(["-q", "run", str(SCENARIOS / "servo_press.toml"), "--stop-time", "0.02",
                 "--fmus", str(fmu_dir), "--out", str(tmp_path),
                 "--set", "press.F_max=6e4", "--set", "motor.u=200",
                 "--set", "master.step=2e-3", "--set", "master.extrapolation=1"]) == 0
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["components"]["press"]["parameters"]["F_max"] == 6e4
    assert "u" not in side["components"]["motor"]["parameters"]
    assert side["master"]["step"] == 2e-3 and side["master"]["extrapolation"] == 1
    assert side["rows"] == 11
    assert main(["run", str(SCENARIOS / "servo_press.toml"), "--out", str(tmp_path / "x"),
                 "--set", "master.step=-1"]) == 2
    assert "must be > 0" in capsys.readouterr().err


def test_warnings_are_shown_without_file_paths(capsys):
    import warnings

    from crankfmu.cli import setup_logging
    setup_logging(0)
    warnings.warn("something odd", RuntimeWarning)
    err = capsys.readouterr().err
    assert err.strip() == "warning: RuntimeWarning: something odd"
    warnings.warn("iterative master: not converged")
    assert capsys.readouterr().err.strip() == "warning: iterative master: not converged"
    setup_logging(-2)
    warnings.warn("hidden", RuntimeWarning)
    assert capsys.readouterr().err == ""
    setup_logging(0)


def test_a_build_names_its_sources_and_warns_when_the_tree_differs(tmp_path, capsys):
    """A non-editable install builds FMUs from its own copy; a source tree beside the scene
    whose FMU sources differ is named in a warning (an edit there would be thrown away)."""
    import shutil

    from crankfmu.cli import setup_logging
    from crankfmu.system.wiring import tree_differences, warn_if_tree_differs
    from crankfmu.fmu.build import PACKAGE_DIR
    tree = tmp_path / "tree"
    shutil.copytree(PACKAGE_DIR, tree / "sources" / "crankfmu",
                    ignore=shutil.ignore_patterns("__pycache__"))
    assert tree_differences(tree / "sources" / "crankfmu") == []
    assert tree_differences(PACKAGE_DIR) == []  # the package itself
    motor = tree / "sources" / "crankfmu" / "models" / "dc_motor" / "dc_motor.py"
    motor.write_text(motor.read_text() + "# an edit\n")
    assert tree_differences(tree / "sources" / "crankfmu") == ["models/dc_motor/dc_motor.py"]
    setup_logging(0)
    warn_if_tree_differs(tree)
    err = capsys.readouterr().err
    assert err.startswith("warning: the FMUs are built from the installed crankfmu at ")
    assert "models/dc_motor/dc_motor.py" in err and "pip install -e" in err


def test_verbosity_and_the_build_message(tmp_path, capsys):
    from crankfmu.cli import main
    fmus = tmp_path / "fmus"
    assert main(["run", str(SCENARIOS / "servo_press.toml"), "--stop-time", "0.01", "--fmus",
                 str(fmus), "--out", str(tmp_path / "a"), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert f"building {fmus / 'DcServoMotor.fmu'} (FMU missing) from " in err
    assert main(["-q", "run", str(SCENARIOS / "servo_press.toml"), "--stop-time", "0.01",
                 "--fmus", str(tmp_path / "fmus2"), "--out", str(tmp_path / "b")]) == 0
    assert "building" not in capsys.readouterr().err
