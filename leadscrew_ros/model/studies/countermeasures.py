# SPDX-License-Identifier: Apache-2.0
"""What to change: design and operating parameters ranked by how much a 10 % change in the
favourable direction lowers P(squeak), each with the new P computed (not extrapolated).

Both directions of each parameter are evaluated with the fast estimator
(`probability.linearised`) on the same samples, the geometry rebuilt where the parameter changes
it; the favourable direction is the one with the lower P. A change that leaves the valid
parameter domain or the model's validity is not offered. Besides the design and operating
parameters, the friction of the pairing (grease, coating): the Stribeck drop mu_s - mu_k
('friction_drop', mu_k held) and the decay constant d.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..physics.parameters import ParameterError
from ..squeak_model import OperatingPointError, SqueakModel
from ..uncertainty.scatter import Samples
from .probability import linearised

DESIGN = ("radius_m", "helix_angle_rad", "nut_position_m", "nut_length_m", "modal_damping")
FRICTION = ("friction_drop", "friction_decay_s_m")
OPERATING = ("speed_rad_s", "load_n")
STEP = 0.10  # relative change offered
MIN_DROP = 0.01  # the advice line names changes that gain this
_WORDS = {
    "radius_m": "the radius",
    "helix_angle_rad": "the helix angle",
    "nut_position_m": "the nut position",
    "nut_length_m": "the nut length",
    "modal_damping": "the damping",
    "friction_drop": "mu_s - mu_k",
    "friction_decay_s_m": "the friction decay d",
    "speed_rad_s": "the speed",
    "load_n": "the load",
}


@dataclass(frozen=True)
class Countermeasure:
    """One parameter changed by `STEP` in its favourable direction.

    Attributes
    ----------
    name : str
        `ScrewParameters` field, 'friction_drop' (mu_s - mu_k), or 'speed_rad_s' / 'load_n'
        (their magnitude).
    factor : float
        Multiplier of the parameter (1 + STEP or 1 - STEP).
    probability : float
        P(squeak) after the change.
    """

    name: str
    factor: float
    probability: float

    @property
    def text(self) -> str:
        """'raise the radius' / 'lower the nut position'."""
        return f"{'raise' if self.factor > 1 else 'lower'} {_WORDS[self.name]}"


def countermeasures(
    model: SqueakModel, speed_rad_s: float, load_n: float, samples: Samples
) -> tuple[float, list[Countermeasure]] | None:
    """P(squeak) now, and the changes that lower it, most effective first.

    Parameters
    ----------
    model : SqueakModel
        The nominal model.
    speed_rad_s, load_n : float
        Operating point [rad/s], [N].
    samples : Samples
        Scatter samples (friction and damping), shared by every evaluation.

    Returns
    -------
    tuple of (float, list of Countermeasure) or None
        None outside the model's validity; else the current P and the changes with a lower P,
        sorted by the new P (ascending).
    """
    now = linearised(model, speed_rad_s, load_n, samples)
    if now is None:
        return None
    found = []
    for name in DESIGN + FRICTION + OPERATING:
        best = None
        for factor in (1 + STEP, 1 - STEP):
            try:  # a change beyond a parameter's range or the plausible load is no advice
                changed, speed, load = changed_by(model, speed_rad_s, load_n, name, factor)
                e = linearised(changed, speed, load, samples)
            except (ParameterError, OperatingPointError):
                continue
            if (
                e is not None
                and e.probability < now.probability
                and (best is None or e.probability < best.probability)
            ):
                best = Countermeasure(name, factor, e.probability)
        if best is not None:
            found.append(best)
    return now.probability, sorted(found, key=lambda c: (c.probability, c.name))


def changed_by(
    model: SqueakModel, speed_rad_s: float, load_n: float, name: str, factor: float
) -> tuple[SqueakModel, float, float]:
    """The model and operating point with parameter `name` multiplied by `factor`.

    Raises
    ------
    ParameterError
        The change leaves the valid parameter domain.
    """
    p = model.params
    if name == "speed_rad_s":
        return model, speed_rad_s * factor, load_n
    if name == "load_n":
        return model, speed_rad_s, load_n * factor
    if name == "friction_drop":
        return (
            model.with_params(mu_static=p.mu_kinetic + factor * (p.mu_static - p.mu_kinetic)),
            speed_rad_s,
            load_n,
        )
    return model.with_params(**{name: getattr(p, name) * factor}), speed_rad_s, load_n


def advice_text(probability: float, measures: list[Countermeasure], top: int = 2) -> str:
    """One line: 'P(squeak) 0.13: lower the speed or raise the damping', naming the `top`
    changes that lower P by at least MIN_DROP."""
    head = f"P(squeak) {probability:.2f}"
    useful = [m for m in measures if probability - m.probability >= MIN_DROP][:top]
    if not useful:
        return head + (
            f": no 10 % change of one parameter lowers it by {MIN_DROP:g}"
            if probability > 0
            else ""
        )
    return f"{head}: " + " or ".join(m.text for m in useful)
