"""Identification of a recorded swing, with residual-driven model discovery.

Each step is a module; ``pipeline.identify`` runs them in this order:

    preparation → angle unwrapped, noise floor, glitches removed, swing window
                  (release … stop, or a long gap after which the swing does
                  not clearly continue)                         ``prepare``
    baseline    → the declared model fitted to the whole record, from the
                  swing's frequency and every alias the sampling allows
                  (``starts.rival_frequencies``); a robust (soft-L1) loss from
                  then on when wild samples are left (``outliers``)
    discovery   → each round, every candidate effect is scored against the
                  current fit (a Lagrange-multiplier test) and those that
                  could lower BIC are fitted side by side (``threads``); the
                  one with the lowest BIC is added if it lowers BIC by more
                  than the margin                               ``discover``
    rivals      → an effect that moved ω_n by more than its σ is withdrawn when
                  the model it ends in gives another ω_n in each half of the
                  record (``hold_across``); a restoring law the loop offers is
                  added where the kept model's halves disagree and the law
                  makes them agree (``demanded_law``); a law the rig does not offer is
                  fitted in place of an effect that mimics it (``law_rival``);
                  with the halves and the near rivals, the model's form
                  (``model_form``) enters ω_n's uncertainty
    guard       → a final model that fits worse than a model it contains left
                  the optimum: refitted from that model's values, or that
                  model kept (``starts.keep_nested_order``)
    flags       → the facts a reader must not miss (``raise_flags``); a fit
                  whose residual is comparable to the swing does not follow it
                  (``follows_swing``: fit_not_converged)
    report      → before/after, the evidence of every step, and what is left
                  unexplained, in words (``describe``), kept apart from the fitting
    assembly    → the ``IdentificationResult`` (``assemble``), its quantities
                  and budgets from ``quantities`` (which the joint fit of
                  several releases uses too)

The entry points below are imported on first use (``measurement._lazy``): the
settings (``Options``) load no numerics. The joint fit of several releases
(``measurement.joint``) uses ``quantities``, ``rivals.fallback`` and ``threads``.
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

#: public name → the module of this package that defines it
_WHERE = {"Options": "options", "identify": "pipeline"}

__getattr__, __dir__ = lazy_exports(__name__, globals(), _WHERE)

if TYPE_CHECKING:  # pragma: no cover
    from .options import Options
    from .pipeline import identify

__all__ = ["Options", "identify"]
