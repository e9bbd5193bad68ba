"""Planner specs: which planner an evaluation flies, with which options, under which label.

This module owns :class:`PlannerSpec` (a registry name, its JSON-safe keyword options and the
label that names it in results) and the command line's planner syntax
``[LABEL:]NAME[=CHECKPOINT]`` (:meth:`PlannerSpec.parse`, :func:`as_specs`). The evaluation
runner (:mod:`ipp_toolkit.runs.evaluation`), the result store and the reports read specs from here.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["PlannerSpec", "as_specs"]


@dataclass(frozen=True)
class PlannerSpec:
    """A planner to evaluate: a registry name, its keyword options and its label.

    Attributes:
        name: registry name, e.g. ``"ig"`` or ``"coma"`` (see :func:`make_planner`).
        options: keyword options for ``make_planner`` (e.g. ``{"checkpoint": "run/ckpt.pt"}``);
            must be JSON-serialisable (path-like values are stored as strings).
        label: name of the planner in results and tables; defaults to ``name``.
    """

    name: str
    options: dict = field(default_factory=dict)
    label: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"planner name must be a non-empty string, got {self.name!r}")
        if not isinstance(self.options, Mapping):
            raise ValueError(f"options of planner {self.name!r} must be a mapping, "
                             f"got {self.options!r}")
        options = {str(k): os.fspath(v) if isinstance(v, os.PathLike) else v
                   for k, v in self.options.items()}
        try:
            json.dumps(options, allow_nan=False)
        except (TypeError, ValueError) as err:
            raise ValueError(f"options of planner {self.name!r} must be JSON-serialisable "
                             f"(they are stored with the results): {err}") from None
        object.__setattr__(self, "options", options)
        if self.label is not None and (not isinstance(self.label, str) or not self.label.strip()):
            raise ValueError(f"planner label must be a non-empty string or None, "
                             f"got {self.label!r}")
        for text, what in ((self.label, "label"), (self.name, "name")):
            # A newline or tab would break summary.md's table and results.csv's rows.
            if isinstance(text, str) and any(ord(c) < 32 or 127 <= ord(c) < 160 for c in text):
                raise ValueError(f"planner {what} {text!r} holds a control character (a "
                                 "newline, a tab, ...); labels name table rows and files")

    def __hash__(self) -> int:
        return hash((self.name, json.dumps(self.options, sort_keys=True), self.label))

    @property
    def effective_label(self) -> str:
        """The label used in results: ``label`` or, when it is None, ``name``."""
        return self.label if self.label is not None else self.name

    @classmethod
    def parse(cls, text: str) -> PlannerSpec:
        """Parse ``"[LABEL:]NAME[=CHECKPOINT]"`` (the command line's planner syntax).

        ``"ig"`` gives name ``ig`` without options; ``"coma=runs/x/ckpt.pt"`` gives name
        ``coma`` with ``options={"checkpoint": "runs/x/ckpt.pt"}``. The label is the name
        unless a ``LABEL:`` prefix names it, so two policies of one planner can be compared:
        ``"coma,coma-mixed:coma=runs/mixed/best.pt"``.
        """
        syntax = "[LABEL:]NAME or [LABEL:]NAME=CHECKPOINT"
        if not isinstance(text, str) or not text.strip():
            raise ValueError(f"planner must be {syntax}, got {text!r}")
        head, sep, value = (part.strip() for part in text.strip().partition("="))
        label, colon, name = (part.strip() for part in head.rpartition(":"))
        if not name or (sep and not value) or (colon and not label):
            raise ValueError(f"planner must be {syntax}, got {text!r}")
        return cls(name=name, options={"checkpoint": value} if sep else {},
                   label=label if colon else name)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe description ``{"name", "options", "label"}`` (label resolved)."""
        return {"name": self.name, "options": dict(self.options), "label": self.effective_label}


def as_specs(planners: str | Sequence[str | PlannerSpec]) -> list[PlannerSpec]:
    """The specs of ``planners``: one comma-separated string, one spec, or a sequence of
    names (:meth:`PlannerSpec.parse` syntax) and specs; ValueError when none is given."""
    if isinstance(planners, str | PlannerSpec):
        items: list[Any] = ([p for p in planners.split(",") if p.strip()]
                            if isinstance(planners, str) else [planners])
    else:
        items = list(planners)
    if not items:
        raise ValueError("no planner given: pass at least one planner name or PlannerSpec")
    specs = []
    for item in items:
        if isinstance(item, PlannerSpec):
            specs.append(item)
        elif isinstance(item, str):
            specs.append(PlannerSpec.parse(item))
        else:
            raise ValueError(f"a planner must be a name or a PlannerSpec, got {item!r}")
    return specs
