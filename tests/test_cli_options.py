"""The command line: every option a command accepts is read by that command and follows the
convention of docs/cli.md (checked here by walking the parsers), the page lists them all, and
--set reaches a parameter, a constant input and a master key."""
from __future__ import annotations

import argparse
import inspect
import json
import re

import pytest

from tests.conftest import ROOT, SCENARIOS


def _cli_doc():
    """scripts/cli_doc.py as a module: the parser walk and the docs page it writes."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("cli_doc", ROOT / "scripts" / "cli_doc.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


CLI_DOC = _cli_doc()
_commands = CLI_DOC.leaves  # (command path, parser) for every leaf subcommand


def _reads(source: str, dest: str) -> bool:
    """args.dest, or getattr(args, ...) with the name "dest" written in the same code (a loop
    over option names), or a master's declared option read by the loop over the declarations
    (commands.options.master_options_from)."""
    from crankfmu.masters import all_options
    declared = dest.startswith("master_") and dest[len("master_"):] in all_options()
    return re.search(rf"args\.{dest}\b", source) is not None or \
        ("getattr(args, " in source and f'"{dest}"' in source) or \
        (declared and 'getattr(args, f"master_{name}"' in source)


def test_every_option_is_used_by_its_command():
    """Walks the parsers: for each option of each command, its handler (with the shared helpers
    of commands/options.py when the handler calls them, and run_command for -q and -v) reads
    it."""
    from crankfmu import cli
    from crankfmu.commands import options
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
        if func.__name__ == "run_command":  # run's handler passes args to its --target part
            source = inspect.getsource(inspect.getmodule(func))
        for helper in (options.load_with_options, options.master_options_from,
                       options.progress_lines):
            if helper.__name__ in source:
                source += inspect.getsource(helper)
        for action in sub._actions:
            if action.dest in ("help", "verbose_after", "quiet_after"):
                assert action.dest == "help" or _reads(main_source, action.dest)
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
    assert "--step" not in opts["accuracy"]
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


# -- the convention of docs/cli.md, on every parser ------------------------------------------------
FIGURE_COMMANDS = {("run",), ("reference",), ("accuracy",), ("sweep",), ("compare",)} | {
    ("analyze", s) for s in ("press", "impact", "planetary", "stopping", "mill-stand", "hammer",
                             "flywheel")}
JOBS_COMMANDS = {("run",), ("sweep",), ("accuracy",), ("compare",)}


def _parsers():
    """(path, parser) of the top level and of every command: all the options there are."""
    from crankfmu.cli import build_parser
    parser = build_parser()
    return parser, [((), parser)] + list(_commands(parser))


def _options(sub):
    return [a for a in sub._actions
            if a.dest != "help" and not isinstance(a, argparse._SubParsersAction)]


def test_every_argument_and_option_has_help():
    """Before: `structure`'s argument and `build --dest` had none ("output folder" said nothing
    of FMI 3.0's subfolder)."""
    _, parsers = _parsers()
    missing = [f"crankfmu {' '.join(p)} {a.option_strings or a.dest}" for p, sub in parsers
               for a in _options(sub) if len((a.help or "").split()) < 3]
    assert missing == []


def test_plot_is_a_flag_and_opt_in_everywhere():
    """Before: sweep drew sweep.png unless --no-plot; accuracy and compare always drew."""
    _, parsers = _parsers()
    found = {}
    for path, sub in parsers:
        for a in _options(sub):
            assert not any(o.startswith("--no-plot") for o in a.option_strings), path
            if "--plot" in a.option_strings:
                found[path] = (a.nargs, a.default, a.const)
    assert set(found) == FIGURE_COMMANDS
    assert set(found.values()) == {(0, False, True)}  # store_true


def test_jobs_has_one_meaning_and_one_default():
    """Before: --jobs defaulted to 1 in run and to every core elsewhere. Now 1 (this process)
    everywhere, N > 1 processes, 0 one per core."""
    from crankfmu.commands.options import jobs_count
    parser, parsers = _parsers()
    jobs = {path: a for path, sub in parsers for a in _options(sub) if a.dest == "jobs"}
    assert set(jobs) == JOBS_COMMANDS
    for path, a in jobs.items():
        assert a.default == 1 and a.type is jobs_count, path
        assert "1 (default) runs everything in this process" in a.help and \
            "0 one per core" in a.help, path
    assert jobs_count("0") == 0 and jobs_count("3") == 3
    with pytest.raises(argparse.ArgumentTypeError):
        jobs_count("-1")


def test_target_is_only_the_search():
    """--target chooses a setting (run); accuracy's error to meet is --meet, and unset by
    default (before: --target 0.001, so every table ended with a choice nobody asked for)."""
    _, parsers = _parsers()
    takers = {path for path, sub in parsers for a in _options(sub) if "--target" in a.option_strings}
    assert takers == {("run",)}
    meet = [a for p, sub in parsers if p == ("accuracy",) for a in _options(sub)
            if "--meet" in a.option_strings]
    assert len(meet) == 1 and meet[0].default is None


def test_units_and_defaults_are_in_the_help():
    """An option taking a number of a physical quantity says its unit in brackets ([s], [1]...;
    a master's declared option carries its unit in the declaration), and an option with a
    default says it."""
    from crankfmu.masters import all_options
    declared = {f"master_{n}": o for n, o in all_options().items()}
    _, parsers = _parsers()
    no_unit, no_default = [], []
    for path, sub in parsers:
        for a in _options(sub):
            where = f"crankfmu {' '.join(path)} {a.option_strings[0] if a.option_strings else a.dest}"
            numbers = a.type is float or getattr(a.type, "__name__", "") == "_floats"
            if numbers and a.dest not in declared and not re.search(r"\[[^\]]+\]", a.help):
                no_unit.append(where)
            if a.dest in declared:
                assert declared[a.dest].unit, where
            if a.default not in (None, False, [], 0, argparse.SUPPRESS) and \
                    "default" not in a.help:
                no_default.append(where)
    assert no_unit == [] and no_default == []


def test_quiet_and_verbose_before_and_after_every_command():
    """`crankfmu run SCENE -q` works (before: "unrecognized arguments: -q"): -q and -v are taken
    before the command and after it, by every command, and counted together."""
    from crankfmu.cli import run_command
    parser, parsers = _parsers()
    for path, sub in parsers[1:]:
        argv = list(path)
        for a in sub._actions:
            if not a.option_strings and a.dest != "help":
                argv.append("x.toml")
            elif a.required:
                argv += [a.option_strings[0], "c.p=1"]
        args = parser.parse_args(["-q", *argv, "-q", "-v", "-q"])
        assert (args.quiet, args.quiet_after, args.verbose_after) == (1, 2, 1), path
    source = inspect.getsource(run_command)
    assert "args.verbose + args.verbose_after - args.quiet - args.quiet_after" in source


def test_run_quiet_after_the_scene(tmp_path, fmu_dir, capsys):
    from crankfmu.cli import main
    assert main(["run", str(SCENARIOS / "servo_press.toml"), "--stop-time", "0.01", "--fmus",
                 str(tmp_path / "fmus"), "--out", str(tmp_path), "-q"]) == 0
    out = capsys.readouterr()
    assert "building" not in out.err and "wrote" in out.out


def test_no_help_names_a_source_folder():
    """Before: the top-level description spoke of "crankfmu/commands/"."""
    parser, parsers = _parsers()
    texts = [parser.description] + [a.help or "" for _, sub in parsers for a in _options(sub)]
    assert not [t for t in texts if "crankfmu/" in t or "sources/" in t]


def test_docs_cli_page_lists_every_option():
    """docs/cli.md's reference part is what scripts/cli_doc.py writes from the parsers now."""
    cli_doc = CLI_DOC
    page = cli_doc.PAGE.read_text()
    assert cli_doc.page_with(cli_doc.generated(), page) == page, \
        "docs/cli.md is stale: python scripts/cli_doc.py"


def test_a_run_warns_when_the_tree_beside_the_scene_differs(tmp_path, fmu_dir, capsys):
    """After a plain `pip install .` an edited model in the source tree was used by nobody and
    `crankfmu run` said nothing (its FMUs were current for the installed copy, so nothing was
    rebuilt); only `crankfmu build` warned. Now the run warns too, once."""
    import shutil

    from crankfmu.cli import main
    from crankfmu.fmu.build import PACKAGE_DIR
    from crankfmu.system import wiring
    tree = tmp_path / "tree"
    shutil.copytree(PACKAGE_DIR, tree / "sources" / "crankfmu",
                    ignore=shutil.ignore_patterns("__pycache__"))
    (tree / "scenarios").mkdir()
    shutil.copy(SCENARIOS / "servo_press.toml", tree / "scenarios")
    motor = tree / "sources" / "crankfmu" / "models" / "dc_motor" / "dc_motor.py"
    motor.write_text(motor.read_text() + "# an edit\n")
    wiring._TREES_CHECKED.discard(tree)
    command = ["run", str(tree / "scenarios" / "servo_press.toml"), "--stop-time", "0.01",
               "--fmus", str(fmu_dir), "--out", str(tmp_path / "out"), "--no-estimate"]
    assert main(command) == 0
    err = capsys.readouterr().err
    assert "building" not in err  # the FMUs were current: the warning is not the build's
    assert err.count("warning: the FMUs are built from the installed crankfmu at ") == 1
    assert "models/dc_motor/dc_motor.py" in err
