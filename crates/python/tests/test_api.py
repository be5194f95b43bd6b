"""The package's surface: the type stubs match the real signatures, everything has a docstring,
and the keyword defaults are the command line's."""

import ast
import inspect
import re
import subprocess
from pathlib import Path

import ferret

STUB = Path(ferret.__file__).parent / "_ferret.pyi"


def stub_tree():
    return ast.parse(STUB.read_text())


def stub_params(fn: ast.FunctionDef):
    """(name, kind, default) of a stub's parameters, `self` left out."""
    a = fn.args
    out = []
    positional = a.posonlyargs + a.args
    defaults = [None] * (len(positional) - len(a.defaults)) + list(a.defaults)
    for arg, d in zip(positional, defaults):
        if arg.arg != "self":
            out.append((arg.arg, "positional", None if d is None else ast.literal_eval(d)))
    for arg, d in zip(a.kwonlyargs, a.kw_defaults):
        out.append((arg.arg, "keyword", None if d is None else ast.literal_eval(d)))
    return out


def runtime_params(obj):
    out = []
    for p in inspect.signature(obj).parameters.values():
        if p.name == "self":
            continue
        kind = "keyword" if p.kind is p.KEYWORD_ONLY else "positional"
        out.append((p.name, kind, None if p.default is p.empty else p.default))
    return out


def stub_items():
    for node in stub_tree().body:
        if isinstance(node, ast.FunctionDef):
            yield node.name, getattr(ferret, node.name), node
        elif isinstance(node, ast.ClassDef):
            cls = getattr(ferret, node.name)
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and not item.name.startswith("__len"):
                    is_property = any(
                        getattr(d, "id", None) == "property" for d in item.decorator_list
                    )
                    name = f"{node.name}.{item.name}"
                    if is_property:
                        yield name, getattr(cls, item.name), None
                    elif item.name == "__init__":
                        yield name, cls, item
                    else:
                        yield name, getattr(cls, item.name), item


def test_every_stub_names_a_real_function_with_its_signature():
    checked = 0
    for name, obj, fn in stub_items():
        if fn is not None:
            assert stub_params(fn) == runtime_params(obj), name
            checked += 1
    assert checked >= 15


def test_the_stub_lists_everything_the_module_exports():
    names = {n.name for n in stub_tree().body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    exported = {n for n in ferret.__all__ if not n.isupper() and not n.startswith("__")}
    assert exported == names


def test_everything_has_a_docstring():
    assert ferret.__doc__ and ferret._ferret.__doc__
    for name, obj, _ in stub_items():
        assert (obj.__doc__ or "").strip(), name
    for name in ferret.__all__:
        obj = getattr(ferret, name)
        if callable(obj):
            assert (obj.__doc__ or "").strip(), name


def test_keyword_defaults_are_the_command_lines(ferret_bin):
    help_text = subprocess.run(
        [ferret_bin, "eval", "--help"], capture_output=True, text=True
    ).stdout
    # clap wraps long help; join it so that each option's text is on one line.
    flat = " ".join(help_text.split())

    def cli_default(option):
        m = re.search(rf"--{option} <[^>]+> .*?\[default: ([^\]]+)\]", flat)
        assert m, option
        return m.group(1)

    ev = inspect.signature(ferret.evaluate).parameters
    for option in [
        "resolution",
        "robot-radius",
        "wall-thickness",
        "max-containers",
        "exact-max",
        "search-cost",
        "seed",
        "reveal-fraction",
    ]:
        assert float(cli_default(option)) == ev[option.replace("-", "_")].default, option
    assert cli_default("strategies") == ferret.DEFAULT_STRATEGIES
    s = inspect.signature(ferret.Search).parameters
    d = inspect.signature(ferret.House.distances).parameters
    for k in ["resolution", "robot_radius", "wall_thickness"]:
        assert s[k].default == d[k].default == ev[k].default
    smoothing = subprocess.run(
        [ferret_bin, "prior", "train", "--help"], capture_output=True, text=True
    ).stdout
    m = re.search(r"--smoothing <[^>]+>.*?\[default: ([^\]]+)\]", " ".join(smoothing.split()))
    assert (
        m
        and float(m.group(1))
        == inspect.signature(ferret.Prior.train).parameters["smoothing"].default
    )


def test_py_typed_ships():
    assert (Path(ferret.__file__).parent / "py.typed").is_file()
