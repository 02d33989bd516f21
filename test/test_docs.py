# SPDX-License-Identifier: Apache-2.0
"""The public model API has numpydoc docstrings: every argument under Parameters, a Returns
section wherever something is returned, every field of the result types under Attributes (with
its unit for `ScrewParameters`). numpydoc itself is not a dependency: the sections are parsed
here, by their underlined headings."""

from __future__ import annotations

import dataclasses
import inspect
import re

import pytest

from leadscrew_ros.model import squeak_model
from leadscrew_ros.model.acoustics import detection, synthesis, tonality
from leadscrew_ros.model.acoustics.agreement import Agreement, agreement
from leadscrew_ros.model.nonlinear import friction_force, transient, transient_analysis
from leadscrew_ros.model.physics import parameters, stability
from leadscrew_ros.model.studies import sweep, tracking
from leadscrew_ros.model.physics.parameters import ScrewParameters, field_info, field_names
from leadscrew_ros.review import fleet, fleetreport

FUNCTIONS = [
    squeak_model.SqueakModel,                  # the class docstring documents __init__
    squeak_model.SqueakModel.with_params,
    squeak_model.SqueakModel.with_scatter,
    squeak_model.SqueakModel.validity_code,
    squeak_model.SqueakModel.validity,
    squeak_model.SqueakModel.state_matrix,
    squeak_model.SqueakModel.predict,
    squeak_model.SqueakModel.predict_many,
    squeak_model.Prediction.as_dict,
    squeak_model.check_operating_point,
    ScrewParameters.with_,
    ScrewParameters.geometry_only,
    ScrewParameters.as_dict,
    stability.ModeResult.as_dict,
    sweep.sweep,
    sweep.stability_map,
    sweep.growth_field,
    sweep.refine_crossings,
    sweep.find_roots,
    sweep.unstable_intervals,
    sweep.SweepResult.as_dict,
    sweep.SweepResult.probability_crossings,
    sweep.MapResult.as_dict,
    sweep.MapResult.probability_contours,
    sweep.probability_field,
    sweep.level_crossings,
    tracking.track_modes,
    friction_force.HelixFriction,
    friction_force.HelixFriction.velocity,
    friction_force.HelixFriction.force,
    transient.ModalEquations,
    transient.simulate,
    transient_analysis.analyse,
    transient_analysis.fit_growth,
    transient_analysis.linear_counterparts,
    transient_analysis.TransientAnalysis.as_dict,
    fleet.find_logs,                        # the fleet review's API
    fleet.review_one,
    fleet.review_logs,
    fleetreport.write_fleet,
    detection.detect,                       # the bench microphone (acoustics)
    detection.StreamingDetector,
    detection.StreamingDetector.push,
    detection.frames_heard,
    detection.Episode.as_dict,
    detection.Detection.as_dict,
    agreement,
    Agreement.as_dict,
    synthesis.microphone,
    tonality.tnr_limit_db,
    tonality.pr_limit_db,
    tonality.short_time_psd,
    tonality.ToneAnalyzer,
]
RECORDS = [ScrewParameters, squeak_model.Prediction, stability.ModeResult, sweep.GrowthField,
           sweep.SweepResult, sweep.MapResult, tracking.Branch, transient.TransientSettings,
           transient.TransientResult, transient_analysis.LinearFit,
           transient_analysis.LimitCycle, transient_analysis.TransientAnalysis,
           fleet.FleetSettings, detection.Episode, detection.Detection, Agreement]
PROPERTIES = [(squeak_model.SqueakModel, ("labels", "critical_speed_rad_s")),
              (squeak_model.Prediction, ("valid", "stable", "squeak_modes",
                                      "unstable_frequencies_hz", "max_growth_rate")),
              (ScrewParameters, ("n_modes", "lead_per_rad_m", "nut_travel_m")),
              (sweep.SweepResult, ("max_growth_rate", "probability")),
              (tracking.Branch, ("label", "peak_growth", "typical_frequency_hz", "squeaks",
                                  "squeak_frequency_hz", "squeak_text"))]


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
    """Entry names of a Parameters/Attributes section ('name : type' or a bare name at the
    section's indentation) -> the entry's text."""
    out: dict[str, str] = {}
    name = None
    for line in section:
        if line and not line[0].isspace():
            name = line.split(" : ")[0].strip()
            out[name] = line
        elif name is not None:
            out[name] += "\n" + line
    return out


def documented_name(p: inspect.Parameter) -> str:
    return {p.VAR_KEYWORD: "**", p.VAR_POSITIONAL: "*"}.get(p.kind, "") + p.name


def _id(obj) -> str:
    return obj.__qualname__


@pytest.mark.parametrize("func", FUNCTIONS, ids=_id)
def test_every_argument_is_documented(func):
    doc = sections(func.__doc__)
    params = [p for p in inspect.signature(func).parameters.values() if p.name != "self"]
    if params:
        assert "Parameters" in doc, f"{func.__qualname__}: no Parameters section"
        listed = entries(doc["Parameters"])
        for p in params:
            assert documented_name(p) in listed, \
                f"{func.__qualname__}: argument {documented_name(p)} not documented"
            assert listed[documented_name(p)].count("\n") >= 1, \
                f"{func.__qualname__}: argument {p.name} has no description"
        extra = set(listed) - {documented_name(p) for p in params}
        assert not extra, f"{func.__qualname__}: documents arguments it does not take: {extra}"


@pytest.mark.parametrize("func", FUNCTIONS, ids=_id)
def test_returns_section_where_something_is_returned(func):
    if inspect.isclass(func):                  # a constructor returns the instance
        return
    annotation = inspect.signature(func).return_annotation
    assert annotation is not inspect.Signature.empty, f"{func.__qualname__}: no return type"
    if annotation not in (None, "None"):
        assert sections(func.__doc__).get("Returns"), f"{func.__qualname__}: no Returns section"


@pytest.mark.parametrize("record", RECORDS, ids=_id)
def test_every_field_is_an_attribute(record):
    names = (record._fields if hasattr(record, "_fields")
             else [f.name for f in dataclasses.fields(record)])
    listed = entries(sections(record.__doc__).get("Attributes", []))
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


@pytest.mark.parametrize("owner,names", PROPERTIES, ids=[o.__qualname__ for o, _ in PROPERTIES])
def test_properties_have_docstrings(owner, names):
    for name in names:
        doc = inspect.getdoc(getattr(owner, name))
        assert doc and doc != inspect.getdoc(property), f"{owner.__qualname__}.{name}"


def test_the_public_api_is_covered():
    """A new public function or method of these modules must be added to the lists above."""
    covered = {f.__qualname__ for f in FUNCTIONS}
    for module, names in ((squeak_model, ("SqueakModel", "check_operating_point")),
                          (sweep, ("sweep", "stability_map", "growth_field", "refine_crossings",
                                   "unstable_intervals", "probability_field", "level_crossings",
                                   "find_roots",
                                   "SweepResult", "MapResult")),
                          (tracking, ("track_modes", "Branch")),
                          (parameters, ("ScrewParameters",))):
        for name in names:
            obj = getattr(module, name)
            if not inspect.isclass(obj):
                assert obj.__qualname__ in covered
                continue
            for attr, member in vars(obj).items():
                if attr.startswith("_") or not inspect.isfunction(member):
                    continue
                assert member.__qualname__ in covered, \
                    f"{member.__qualname__} is public but not checked here"
