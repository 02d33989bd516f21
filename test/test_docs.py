# SPDX-License-Identifier: Apache-2.0
"""The public API has numpydoc docstrings: every name in the `__all__` of every package of
leadscrew_ros, the public methods and properties of the classes among them, and the API that
stays in its module (`MODULE_API`). Every argument under Parameters, a Returns section
wherever something is returned, every field of the result types under Attributes (with its
unit for `ScrewParameters`). numpydoc itself is not a dependency: the sections are parsed
here, by their underlined headings. The Examples of `SqueakModel.predict` run as a doctest."""

from __future__ import annotations

import dataclasses
import doctest
import enum
import importlib
import inspect
import re

import pytest

from leadscrew_ros.model import squeak_model
from leadscrew_ros.model.acoustics import agreement as acoustics_agreement
from leadscrew_ros.model.nonlinear import friction_force, transient, transient_analysis
from leadscrew_ros.model.physics.parameters import ScrewParameters, field_info, field_names
from leadscrew_ros.model.studies import fields, roots, stability_map, sweep
from leadscrew_ros.review import fleet, replay

PACKAGES = (
    "leadscrew_ros",
    "leadscrew_ros.model",
    "leadscrew_ros.model.physics",
    "leadscrew_ros.model.uncertainty",
    "leadscrew_ros.model.studies",
    "leadscrew_ros.model.calibration",
    "leadscrew_ros.model.nonlinear",
    "leadscrew_ros.model.acoustics",
    "leadscrew_ros.live",
    "leadscrew_ros.bag",
    "leadscrew_ros.review",
    "leadscrew_ros.review.calibration",
    "leadscrew_ros.ros",
    "leadscrew_ros.cli",
)
# Public functions and classes that are not re-exported by their package (`studies.sweep.sweep`
# and `review.replay.replay` are named like their modules; the rest are the next level down).
MODULE_API = [
    sweep.sweep,
    sweep.peak_growth,
    sweep.probability_crossings,
    stability_map.stability_map,
    fields.growth_field,
    fields.probability_field,
    fields.GrowthField,
    roots.refine_crossings,
    roots.find_roots,
    roots.unstable_intervals,
    roots.level_crossings,
    roots.refine_level_crossings,
    squeak_model.check_operating_point,
    friction_force.HelixFriction,
    transient.ModalEquations,
    transient.TransientSettings,
    transient_analysis.fit_growth,
    transient_analysis.linear_counterparts,
    transient_analysis.LinearFit,
    transient_analysis.LimitCycle,
    fleet.find_logs,
    fleet.review_one,
    replay.replay,
    acoustics_agreement.agreement,
    acoustics_agreement.nearest_mode,
]


def exported() -> list[tuple[str, object]]:
    """(package.name, object) of every name in the packages' `__all__`; module attributes
    that are not functions or classes (constants, `__version__`) have no docstring of their
    own and are left out."""
    out = []
    for name in PACKAGES:
        package = importlib.import_module(name)
        assert hasattr(package, "__all__"), f"{name} has no __all__"
        for attr in package.__all__:
            obj = getattr(package, attr)
            if inspect.isclass(obj) or inspect.isfunction(obj):
                out.append((f"{name}.{attr}", obj))
    return out


def _records(cls) -> bool:
    """A result/settings type whose fields are its API (dataclass or NamedTuple)."""
    return dataclasses.is_dataclass(cls) or (issubclass(cls, tuple) and hasattr(cls, "_fields"))


def api() -> tuple[list, list, list]:
    """(callables whose arguments are documented, record types, (class, property) pairs)."""
    funcs, records, props, seen = [], [], [], set()
    for obj in [o for _, o in exported()] + MODULE_API:
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if not inspect.isclass(obj):
            funcs.append(obj)
            continue
        if _records(obj):
            records.append(obj)
        elif not issubclass(obj, (BaseException, enum.Enum)):
            funcs.append(obj)  # the class docstring documents __init__
        for attr, member in vars(obj).items():
            if attr.startswith("_"):
                continue
            if isinstance(member, (staticmethod, classmethod)):
                member = member.__func__
            if inspect.isfunction(member):
                funcs.append(member)
            elif isinstance(member, property):
                props.append((obj, attr))
    return funcs, records, props


FUNCTIONS, RECORDS, PROPERTIES = api()


def sections(doc: str | None) -> dict[str, list[str]]:
    """Numpydoc sections of a docstring: heading -> its lines (dedented)."""
    lines = inspect.cleandoc(doc or "").splitlines()
    out: dict[str, list[str]] = {}
    current = None
    for i, line in enumerate(lines):
        if i + 1 < len(lines) and re.fullmatch(r"-{3,}", lines[i + 1].strip()) and line.strip():
            current = line.strip()
            out[current] = []
        elif current is not None and not re.fullmatch(r"-{3,}", line.strip()):
            out[current].append(line)
    return out


def entries(section: list[str]) -> dict[str, str]:
    """Entry names of a Parameters/Attributes section ('name : type', 'a, b : type' or a bare
    name at the section's indentation) -> the entry's text."""
    out: dict[str, str] = {}
    names: list[str] = []
    for line in section:
        if line and not line[0].isspace():
            names = [n.strip() for n in line.split(" : ")[0].split(", ")]  # 'a, b : float'
            out.update(dict.fromkeys(names, line))
        else:
            for name in names:
                out[name] += "\n" + line
    return out


def documented_name(p: inspect.Parameter) -> str:
    return {p.VAR_KEYWORD: "**", p.VAR_POSITIONAL: "*"}.get(p.kind, "") + p.name


def _id(obj) -> str:
    return obj.__qualname__


@pytest.mark.parametrize("func", FUNCTIONS, ids=_id)
def test_every_argument_is_documented(func):
    doc = sections(func.__doc__)
    params = [
        p for p in inspect.signature(func).parameters.values() if p.name not in ("self", "cls")
    ]
    if params:
        assert "Parameters" in doc, f"{func.__qualname__}: no Parameters section"
        listed = entries(doc["Parameters"])
        for p in params:
            assert documented_name(p) in listed, (
                f"{func.__qualname__}: argument {documented_name(p)} not documented"
            )
            assert listed[documented_name(p)].count("\n") >= 1, (
                f"{func.__qualname__}: argument {p.name} has no description"
            )
        extra = set(listed) - {documented_name(p) for p in params}
        assert not extra, f"{func.__qualname__}: documents arguments it does not take: {extra}"


@pytest.mark.parametrize("func", FUNCTIONS, ids=_id)
def test_returns_section_where_something_is_returned(func):
    if inspect.isclass(func):  # a constructor returns the instance
        return
    annotation = inspect.signature(func).return_annotation
    assert annotation is not inspect.Signature.empty, f"{func.__qualname__}: no return type"
    if annotation not in (None, "None"):
        assert sections(func.__doc__).get("Returns"), f"{func.__qualname__}: no Returns section"


@pytest.mark.parametrize("record", RECORDS, ids=_id)
def test_every_field_is_documented(record):
    """Under Attributes, or under Parameters (a dataclass's fields are its constructor's)."""
    names = (
        record._fields
        if hasattr(record, "_fields")
        else [f.name for f in dataclasses.fields(record) if not f.name.startswith("_")]
    )
    doc = sections(record.__doc__)
    listed = {**entries(doc.get("Attributes", [])), **entries(doc.get("Parameters", []))}
    assert sorted(listed) == sorted(names), record.__qualname__


def test_screw_parameters_attributes_state_unit_default_and_range():
    listed = entries(sections(ScrewParameters.__doc__)["Attributes"])
    assert list(listed) == field_names()
    for name in field_names():
        info, text = field_info(name), listed[name]
        assert text.startswith(f"{name} : {info['type']}"), text
        if info["unit"] not in ("", "1"):
            assert f"[{info['unit']}]" in text, text
        if info["lo"] is not None:
            assert f"{info['lo']:g}" in text and f"{info['hi']:g}" in text, text
    assert "Default 0.005, allowed [0.0001, 0.5] m." in listed["radius_m"]
    assert "one of paper, consistent" in listed["formulation"]


@pytest.mark.parametrize(
    "owner,name", PROPERTIES, ids=[f"{o.__qualname__}.{n}" for o, n in PROPERTIES]
)
def test_properties_have_docstrings(owner, name):
    doc = inspect.getdoc(getattr(owner, name))
    assert doc and doc != inspect.getdoc(property), f"{owner.__qualname__}.{name}"


@pytest.mark.parametrize("name,obj", exported(), ids=[n for n, _ in exported()])
def test_every_exported_name_has_a_docstring(name, obj):
    doc = obj.__doc__ or ""  # not inherited; not the signature a dataclass makes up
    assert doc.strip() and not doc.startswith(f"{obj.__name__}("), name


def test_every_public_class_has_a_docstring():
    """Also those no `__all__` lists: every class of every module (AST, nothing imported)."""
    import ast
    from pathlib import Path

    root = Path(squeak_model.__file__).parents[2]
    missing = [
        f"{path.relative_to(root)}:{node.lineno} {node.name}"
        for path in sorted((root / "leadscrew_ros").rglob("*.py"))
        for node in ast.parse(path.read_text(encoding="utf-8")).body
        if isinstance(node, ast.ClassDef)
        and not node.name.startswith("_")
        and not ast.get_docstring(node)
    ]
    assert not missing, missing


def test_the_examples_of_predict_run():
    finder = doctest.DocTestFinder()
    (test,) = finder.find(
        squeak_model.SqueakModel.predict,
        "SqueakModel.predict",
        globs={"SqueakModel": squeak_model.SqueakModel},
    )
    assert test.examples, "SqueakModel.predict has no Examples"
    result = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE).run(
        test
    )
    assert result.failed == 0 and result.attempted == len(test.examples)
