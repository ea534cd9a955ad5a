"""Step 4b, the model that gives the headline ω_n: chosen by the accuracy of ω_n, not by the fit alone.

The discovery loop keeps the model that explains the record (BIC, the halves,
the rivals). An effect can lower BIC by much while it moves ω_n by less than
the variance it adds to it: a law determined by one record only loosely (a
cubic spring extrapolated to zero amplitude, friction traded against a
stiffness) makes one release's ω_n scatter from the next release's where the
plain model's would not. ω_n, from which J is computed, is the focus: of the
declared model and the discovered one, the headline takes the one whose
estimated mean squared error of ω_n is the smaller, the focused information
criterion of Claeskens and Hjort ("The focused information criterion", J.
Am. Stat. Assoc. 98, 2003). The discovered model, the wider one, is taken as
unbiased; each model's variance of ω_n is its fit's σ² plus its model-form
term from the record's halves (a segment-resampling estimate: how far ω_n
moves where the record is looked at in parts) and its rivals; the declared
model's squared bias is its squared distance to the discovered model's ω_n
less the variance of that difference (for nested estimators the difference of
their variances), never below 0:

    MSE_f = u_f²                         (σ_f² + model form, the discovered model's)
    MSE_d = u_d² + max((ω_d − ω_f)² − |u_f² − u_d²|, 0)

Where MSE_d < MSE_f the declared model gives ω_n, with u = √MSE_d: the
discovered model's ω_n is then its rival, named in the model form and carried
into u through the bias term; the discovered model stays what the report
shows (its effects, damping, residual before and after). Discovery is
unchanged: only where ω_n is read from.

Both must estimate one quantity. Where the discovered model holds a
restoring law the rig does not declare (a cubic spring), its ω_n is the law's
small-swing limit and the declared model's the frequency at the record's
own swing: two measurands, not two estimates of one (on the front wheel of
the bicycle set, read from one release's declared model and its sisters'
cubic springs' limits, the releases ended 4–5 u apart where each had been
within 2 u). On a torsion rig ω is read at a reference amplitude
(``measurand``: the calibration's, else the record's own, where a damped
sinusoid, and so the declared model, measures): the discovered model's ω
there and the declared model's ω_n are one measurand, and the choice is
made. Elsewhere (the small-swing limit of a rig's exact law) it is not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..consistency import check_segments
from ..effects import EFFECTS
from ..fit import ModelFit
from ..result import Competitor, ModelForm
from .measurand import read_at
from .rivals import covering
from .starts import Aliases

#: the model that gave ω_n, as the result names it
DECLARED, DISCOVERED = "declared", "discovered"


@dataclass(frozen=True)
class Focus:
    """The model of the headline ω_n.

    fit: the model ω_n is read from; form: its model-form term (``ModelForm``), rivals included;
    chosen: DECLARED or DISCOVERED; mse: the estimated MSE of ω_n under (declared, discovered) model,
    (rad/s)², None where there was no choice (the loop added nothing, or the declared model does not
    follow the swing).
    """

    fit: ModelFit
    form: ModelForm
    chosen: str
    mse: tuple[float, float] | None = None
    #: the swing amplitude ω is read at, rad (0: the small-swing limit: ``measurand``)
    at: float = 0.0

    @property
    def omega_n(self) -> float:
        return read_at(self.fit, self.at)[0]

    @property
    def omega_n_std(self) -> float:
        return read_at(self.fit, self.at)[1]

    @property
    def effects(self) -> tuple[str, ...]:
        return self.fit.model.effect_names


def declared_mse(base: ModelFit, final: ModelFit, form: ModelForm, noise: float,
                 aliases: Aliases, at: float = 0.0) -> tuple[float, float, ModelForm] | None:
    """(MSE of ω_n under the declared model, under the discovered one, the declared model's form), each read at
    the swing amplitude ``at`` (rad; 0: the small-swing limit); None where the declared model's halves cannot be
    fitted."""
    segments = check_segments(base, noise)
    if segments is None:
        return None
    (w_d, s_d), (w_f, s_f) = read_at(base, at), read_at(final, at)
    moved = tuple(Competitor(c.change, c.d_bic, c.weight, c.omega_n, c.omega_n - w_d, c.effects)
                  for c in form.competitors if c not in aliases.rivals)
    # a rival the discovered model carried whole (weight 1: a law the record does not determine, one the
    # releases withdrew) is a value ω_n may have whichever model is read: carried whole from the declared ω_n too
    u_whole = math.sqrt(sum(c.delta**2 for c in moved if c.weight >= 1.0))
    var_d = s_d**2 + segments.u**2 + aliases.u**2 + u_whole**2
    mse_f = s_f**2 + form.u**2
    bias2 = max((w_d - w_f) ** 2 - abs(mse_f - var_d), 0.0)
    rival = Competitor(f"the discovered model ({', '.join(final.model.effect_names)}): its ω_n is the less accurate",
                       final.bic - base.bic, 1.0, w_f, w_f - w_d, final.model.effect_names)
    rivals = (rival, *moved, *aliases.rivals)
    u_rivals = covering(math.sqrt(bias2 + aliases.u**2 + u_whole**2), rivals, s_d)
    return var_d + bias2, mse_f, ModelForm(segments, rivals, u_rivals)


def focus(final: ModelFit, base: ModelFit, form: ModelForm, noise: float, aliases: Aliases,
          base_follows: bool, at: float = 0.0) -> Focus:
    """The model whose ω_n is the more accurate (module doc): the discovered ``final`` or the declared ``base``,
    ω read at the swing amplitude ``at`` (rad; 0: the small-swing limit)."""
    kept = Focus(final, form, DISCOVERED, at=at)
    if base.model.effect_names == final.model.effect_names or not base.success or not base_follows:
        return kept
    if at <= 0 and any(EFFECTS[n].role == "stiffness" for n in final.model.effect_names
                       if n not in base.model.effect_names):
        return kept  # another measurand (module doc)
    judged = declared_mse(base, final, form, noise, aliases, at)
    if judged is None:
        return kept
    mse_d, mse_f, form_d = judged
    if mse_d < mse_f:
        return Focus(base, form_d, DECLARED, (mse_d, mse_f), at)
    return Focus(final, form, DISCOVERED, (mse_d, mse_f), at)
