"""The check's options are one object, :class:`~warp_ccd.usd.CheckOptions`, checked once where it is made.

Each field is checked by its rule in the one table of rules (``runtime/options.OPTIONS``), with that rule's one
message shape; the options the check shares with the pipeline give the same message through either object; the
rules that join options (``min_distance`` with ``continuous``, ``set_a`` with ``set_b``) hold. ``check_usd``,
``check_many`` and ``warp-ccd check`` take the same object (the command's equals the one made in Python from the
same values; its messages name the flags typed); an unknown keyword is a TypeError; the object pickles (a Ray
task gets it as it is). No module of the check or the command bounds a number option by itself.
"""

import ast
import json
import os
import pickle
from dataclasses import fields

import pytest

import warp_ccd as wc
from warp_ccd._src.cli import commands as cli
from warp_ccd._src.cli.common import check_options_from
from warp_ccd._src.runtime.options import OPTIONS, check_option
from warp_ccd.usd import CheckOptions, check_many, check_usd

from conftest import DEFAULT_DEVICE

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CHECKED_ELSEWHERE = {"worlds", "ignore_pairs", "set_a", "set_b"}
"""Fields whose values are prim patterns or pair files: checked by the filters the options make (``set_a``,
``set_b``, ``ignore_pairs``) or by the import that matches them (``worlds``), not by a row of the table."""
BAD = {"number": -1.0, "integer": -1, "flag": "yes", "choice": "nope"}
"""A value each kind of rule refuses (every number and integer option here is bounded below by 0 or 1)."""


def bad_value(name: str):
    return ["nope"] if name == "include_purposes" else BAD[OPTIONS[name].kind]


def expected_message(name: str, value, given_as=None) -> str:
    with pytest.raises(ValueError) as info:
        check_option(name, value[0] if name == "include_purposes" else value, given_as)
    return str(info.value)


# ---------------------------------------------------------------------------------------------
# 1. every field by its rule, one message shape


def test_every_field_has_its_rule_or_its_filter():
    names = {f.name for f in fields(CheckOptions)}
    assert names - set(OPTIONS) == CHECKED_ELSEWHERE
    assert names == {"precision", "min_depth", "count_touching", "segments", "include_invisible", "include_purposes",
                     "tolerance", "progress", "allow_missing", "continuous", "min_distance", "clearance",
                     "self_intersections", "containment", "duplicates", "worlds", "ignore_pairs", "usd_filters",
                     "set_a", "set_b", "read_workers"}


@pytest.mark.parametrize("name", sorted({f.name for f in fields(CheckOptions)} - CHECKED_ELSEWHERE))
def test_each_field_is_checked_by_its_rule(name):
    value = bad_value(name)
    with pytest.raises(ValueError) as info:
        CheckOptions(**{name: value})
    assert str(info.value) == expected_message(name, value)
    assert str(info.value).startswith(f"{name} must be ")
    # The command line names the flag: the same message, another name.
    with pytest.raises(ValueError) as info:
        CheckOptions(**{name: value}, given_as={name: "--flag"})
    assert str(info.value) == expected_message(name, value, "--flag")


@pytest.mark.parametrize("changes", [
    {"tolerance": 0.5}, {"tolerance": -1e-3}, {"clearance": -1.0}, {"clearance": 1e38}, {"clearance": float("nan")},
    {"continuous": True, "min_distance": -0.5}, {"segments": 1},
], ids=repr)
def test_shared_options_give_the_pipelines_message(changes):
    with pytest.raises(ValueError) as pipeline:
        wc.PipelineOptions(**changes)
    with pytest.raises(ValueError) as check:
        CheckOptions(**changes)
    assert str(check.value) == str(pipeline.value)


def test_values_are_normalised():
    o = CheckOptions(min_depth=1, include_purposes="guide", worlds="/World/envs/*", set_a="/A,/B", set_b=["/C"],
                     ignore_pairs=[["/A", "/C"]], read_workers=2, count_touching=True)
    assert o.min_depth == 1.0 and isinstance(o.min_depth, float)
    assert o.include_purposes == ("guide",) and o.worlds == ("/World/envs/*",)
    assert o.set_a == ("/A", "/B") and o.set_b == ("/C",) and o.ignore_pairs == (("/A", "/C"),)
    assert o == CheckOptions(min_depth=1.0, include_purposes=("guide",), worlds=["/World/envs/*"],
                             set_a=["/A", "/B"], set_b="/C", ignore_pairs=[("/A", "/C")], read_workers=2,
                             count_touching=True)
    assert hash(o) == hash(o.replace())


def test_rules_that_join_options():
    with pytest.raises(ValueError, match=r"^min_distance is an option of the continuous check \(continuous=True\), "
                                         r"got 0.1$"):
        CheckOptions(min_distance=0.1)
    with pytest.raises(ValueError, match=r"^--min-distance is an option of the continuous check \(--continuous\)"):
        CheckOptions(min_distance=0.1, given_as={"min_distance": "--min-distance", "continuous": "--continuous"})
    assert CheckOptions(min_distance=0.1, continuous=True).min_distance == 0.1
    for one in ({"set_a": "/A"}, {"set_b": "/B"}):
        with pytest.raises(ValueError, match="set_a and set_b go together"):
            CheckOptions(**one)
    with pytest.raises(ValueError, match="set_a: expected a prim path or pattern starting with '/'"):
        CheckOptions(set_a="World", set_b="/B")


def test_pair_files_are_read_when_the_options_are_made(tmp_path):
    pairs = tmp_path / "pairs.txt"
    pairs.write_text("/World/A /World/C\n")
    o = CheckOptions(ignore_pairs=pairs)
    assert o.ignore_pairs == (str(pairs),) and [(p.a, p.b) for p in o.pair_filters.pairs] == [("/World/A", "/World/C")]
    with pytest.raises(ValueError, match=f"cannot read the ignore-pairs file {tmp_path / 'none.txt'}: no such file"):
        CheckOptions(ignore_pairs=[tmp_path / "none.txt"])
    (tmp_path / "bad.txt").write_text("/World/A\n")
    with pytest.raises(ValueError, match="bad.txt:1: expected two prim paths"):
        CheckOptions(ignore_pairs=str(tmp_path / "bad.txt"))
    # Pickled (to a Ray worker), the pairs go with it: the file is not read again.
    copy = pickle.loads(pickle.dumps(o))
    pairs.unlink()
    assert copy == o and [(p.a, p.b) for p in copy.pair_filters.pairs] == [("/World/A", "/World/C")]


def test_the_options_pickle():
    o = CheckOptions(precision="float64", continuous=True, min_distance=0.01, clearance=0.2, set_a="/A", set_b="/B",
                     ignore_pairs=[("/A", "/C")], include_purposes=("proxy",), read_workers=0)
    copy = pickle.loads(pickle.dumps(o))
    assert copy == o and repr(copy) == repr(o)
    assert copy.pair_filters.set_a == ["/A"] and copy.sweep_options() == o.sweep_options()


def test_the_pipelines_options():
    o = CheckOptions(segments=True, tolerance=1e-4, clearance=0.3, self_intersections=True, continuous=True,
                     min_distance=0.02)
    assert o.pipeline_options() == wc.PipelineOptions(segments=True, tolerance=1e-4, clearance=0.3,
                                                      self_intersections=True)
    assert o.sweep_options() == wc.PipelineOptions(continuous=True, min_distance=0.02)


def test_replace_checks_the_copy():
    o = CheckOptions(clearance=0.1)
    assert o.replace(min_depth=0.5) == CheckOptions(clearance=0.1, min_depth=0.5)
    with pytest.raises(ValueError, match="^min_depth must be a finite number >= 0, got -0.5$"):
        o.replace(min_depth=-0.5)


# ---------------------------------------------------------------------------------------------
# 2. check_usd, check_many and the command take the same object


@pytest.fixture(scope="module")
def stage_path(tmp_path_factory):
    from usd_stages import boxes_stage

    pytest.importorskip("pxr")
    path = tmp_path_factory.mktemp("options") / "boxes.usda"
    boxes_stage(path, {"/World/A": (0.0, 0.0, 0.0), "/World/B": (0.3, 0.0, 0.0), "/World/C": (0.6, 0.0, 0.0)})
    return str(path)


def same_report(a, b) -> bool:
    a, b = a.to_json(), b.to_json()
    a.pop("seconds"), b.pop("seconds")
    return json.dumps(a) == json.dumps(b)


def test_check_usd_and_check_many_take_the_object(stage_path):
    o = CheckOptions(min_depth=0.01, clearance=0.1, set_a="/World/A", set_b="/World/B,/World/C", segments=True)
    by_object = check_usd(stage_path, o, device=DEFAULT_DEVICE)
    by_keywords = check_usd(stage_path, device=DEFAULT_DEVICE, min_depth=0.01, clearance=0.1, set_a="/World/A",
                            set_b="/World/B,/World/C", segments=True)
    assert same_report(by_object, by_keywords) and by_object.clearance == 0.1
    over = check_usd(stage_path, CheckOptions(min_depth=5.0), device=DEFAULT_DEVICE, min_depth=0.01, clearance=0.1,
                     set_a="/World/A", set_b="/World/B,/World/C", segments=True)  # keywords over the object
    assert same_report(over, by_object)
    batch = check_many(stage_path, o, device=DEFAULT_DEVICE, frames_per_task=1)
    assert batch.files[0].tasks == 2 and same_report(batch.files[0].report, by_object)


@pytest.mark.parametrize("call", ["check_usd", "check_many"])
def test_unknown_keywords_and_objects_are_type_errors(stage_path, call):
    run = {"check_usd": check_usd, "check_many": check_many}[call]
    with pytest.raises(TypeError, match=rf"^{call}\(\) got an unexpected keyword argument 'min_dept'$"):
        run(stage_path, min_dept=0.1)
    if call == "check_usd":  # how the command names its flags is no option
        with pytest.raises(TypeError, match=r"^check_usd\(\) got an unexpected keyword argument 'given_as'$"):
            run(stage_path, given_as={})
    with pytest.raises(TypeError, match=f"^{call}: options must be a CheckOptions, got PipelineOptions$"):
        run(stage_path, wc.PipelineOptions())


def test_bad_options_come_before_the_stage(tmp_path):
    with pytest.raises(ValueError, match="^clearance must be"):
        check_usd(tmp_path / "missing.usda", clearance=-1.0)
    with pytest.raises(ValueError, match="^precision must be"):
        check_many(tmp_path / "missing-*.usda", precision="float16")


def parse(*argv):
    return cli._build_parser().parse_args(["check", "anim.usda", *argv])


def test_the_commands_object_is_the_pythons(tmp_path):
    pairs = tmp_path / "pairs.txt"
    pairs.write_text("/World/A /World/C\n")
    args = parse("--precision", "float64", "--min-depth", "0.25", "--count-touching", "--segments",
                 "--include-invisible", "--include-purpose", "guide", "--include-purpose", "proxy", "--allow-missing",
                 "--continuous", "--min-distance", "0.01", "--clearance", "0.5", "--self", "--duplicates",
                 "--worlds", "/World/envs/*", "--ignore-pairs", str(pairs), "--no-usd-filters",
                 "--set-a", "/World/A,/World/B", "--set-b", "/World/C", "--read-workers", "0")
    want = CheckOptions(precision="float64", min_depth=0.25, count_touching=True, segments=True,
                        include_invisible=True, include_purposes=("guide", "proxy"), allow_missing=True,
                        continuous=True, min_distance=0.01, clearance=0.5, self_intersections=True, duplicates=True,
                        worlds="/World/envs/*", ignore_pairs=str(pairs), usd_filters=False,
                        set_a="/World/A,/World/B", set_b="/World/C", read_workers=0, progress=True)
    assert check_options_from(args) == want
    assert check_options_from(parse()) == CheckOptions(progress=True)


def test_argparse_parses_and_the_rules_check():
    """Out-of-range values parse: their rules (the one check) refuse them, named by their flags."""
    args = parse("--min-depth", "-1", "--min-distance", "-1", "--clearance", "-1", "--read-workers", "-1",
                 "--workers", "0", "--frames-per-task", "0", "--precision", "float16", "--include-purpose", "x")
    assert (args.min_depth, args.workers, args.precision, args.include_purposes) == (-1.0, 0, "float16", ["x"])
    for action in cli._build_parser()._subparsers._group_actions[0].choices["check"]._actions:
        if action.dest in OPTIONS:
            assert action.choices is None, action.dest


@pytest.mark.parametrize("argv, message", [
    (["--min-depth", "-1"], "--min-depth must be a finite number >= 0, got -1.0"),
    (["--min-depth", "inf"], "--min-depth must be a finite number >= 0, got inf"),
    (["--clearance", "1e38"], "--clearance must be a finite number in [0, 1e+37], got 1e+38"),
    (["--continuous", "--min-distance", "-2"], "--min-distance must be a finite number >= 0, got -2.0"),
    (["--min-distance", "0.5"], "--min-distance is an option of the continuous check (--continuous), got 0.5"),
    (["--read-workers", "-1"], "--read-workers must be an integer >= 0 or None, got -1"),
    (["--precision", "float16"], "--precision must be one of ['float32', 'float64'], got 'float16'"),
    (["--include-purpose", "x"], "--include-purpose must be one of ['default', 'guide', 'proxy', 'render'], got 'x'"),
    (["--ray", "--workers", "0"], "--workers must be an integer >= 1 or None, got 0"),
    (["--ray", "--frames-per-task", "0"], "--frames-per-task must be an integer >= 1 or None, got 0"),
    (["--set-a", "/World/A"], "set_a and set_b go together (--set-a and --set-b)"),
], ids=lambda v: " ".join(v) if isinstance(v, list) else "")
def test_the_command_names_the_flag(tmp_path, capsys, argv, message):
    """Exit status 2, one line naming the flag typed; before the stage (missing here) is read or Ray started."""
    rc = cli.main(["check", str(tmp_path / "missing.usda"), *argv])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith(f"warp-ccd check: error: {message}") and len(err.strip().splitlines()) == 1, err


def test_check_usd_takes_inputs_besides_the_options():
    import inspect

    params = inspect.signature(check_usd).parameters
    assert list(params) == ["stage_or_path", "options", "frames", "prims", "device", "kwargs"]


# ---------------------------------------------------------------------------------------------
# 3. no module of the check or the command bounds a number option by itself


def test_no_bounds_of_table_options_in_the_check_or_the_command():
    """``number_option`` / ``integer_option`` of an option of the table, or a comparison of an argparse value with
    a bound, would be a second check of it: the table's rule, through ``check_option``, is the one."""
    found = []
    for room in ("check", "cli"):
        folder = os.path.join(ROOT, "warp_ccd", "_src", room)
        for name in sorted(os.listdir(folder)):
            if not name.endswith(".py"):
                continue
            tree = ast.parse(open(os.path.join(folder, name), encoding="utf-8").read())
            for node in ast.walk(tree):
                if not isinstance(node, ast.Call):
                    continue
                func = node.func.id if isinstance(node.func, ast.Name) else getattr(node.func, "attr", "")
                first = node.args[0] if node.args else None
                named = first.value if isinstance(first, ast.Constant) and isinstance(first.value, str) else None
                if func in ("number_option", "integer_option") and (named is None or named in OPTIONS):
                    found.append(f"{room}/{name}:{node.lineno} {func}({named!r})")
                if func == "check_option" and named is not None and named not in OPTIONS:
                    found.append(f"{room}/{name}:{node.lineno} check_option({named!r}) has no rule")
    assert not found
