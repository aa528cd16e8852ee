"""``--help`` in sections: what a newcomer needs first (data and chart, output, validation, starts and workers),
the optimiser's settings grouped after them.

Layer: cli (the rule is in the package docstring). click has no option groups; :class:`SectionedCommand` sorts
a command's options into titled sections by their parameter names, so the options themselves stay plain
``click.option`` declarations (shared ones declared once, in options.py).
"""

from __future__ import annotations

import click

__all__ = ["SECTIONS", "SectionedCommand", "WorkflowGroup", "place_of", "section_of"]

#: section title -> the parameter names (click's, e.g. ``validation`` for --validate) it holds, in print order.
#: An option named nowhere goes to "Other", in declaration order; a command adds its own sections with
#: ``sections=`` (placed before the optimiser's).
SECTIONS: dict[str, tuple[str, ...]] = {
    "Data and chart": ("mapping", "units", "rows", "delimiter", "decimal", "resample", "alignment", "intersample",
                       "substeps", "fix_from", "chart", "diagram"),
    "Output": ("output", "report_path", "plots", "html_path", "fmt", "force", "quiet"),
    "Validation": ("validation", "split", "init_window"),
    "Starts and workers": ("starts", "seed", "workers", "scheduler", "threads"),
    "Optimiser": ("max_iter", "shooting", "shooting_starts", "curve_start", "lm_steps", "lm_bounds", "floor_bias"),
    "Quasi-online": ("online", "window", "average"),
}
OTHER = "Other"


def place_of(name: str, extra: dict[str, tuple[str, ...]] | None = None) -> tuple[str, int]:
    """The title of the section option `name` is printed in, and its rank there: the shared options of a
    section first, in :data:`SECTIONS` order, then those a command adds to it, in its order."""
    for title, names in (extra or {}).items():  # the command's own first: it may put an option elsewhere
        if name in names:
            shared = SECTIONS.get(title, ())
            return title, shared.index(name) if name in shared else 1000 + names.index(name)
    for title, names in SECTIONS.items():
        if name in names:
            return title, names.index(name)
    return OTHER, 0


def section_of(name: str, extra: dict[str, tuple[str, ...]] | None = None) -> str:
    """The title of the section option `name` is printed in."""
    return place_of(name, extra)[0]


class SectionedCommand(click.Command):
    """A click command whose ``--help`` lists its options in :data:`SECTIONS` (plus the command's own
    `sections`: new titles printed before "Optimiser", a known title taking more options), each section only when
    it has options."""

    def __init__(self, *args, sections: dict[str, tuple[str, ...]] | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.sections = dict(sections or {})

    def titles(self) -> list[str]:
        order = list(SECTIONS)
        at = order.index("Optimiser")
        own = [title for title in self.sections if title not in SECTIONS]
        return [*order[:at], *own, *order[at:], OTHER]

    def format_options(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows: dict[str, list[tuple[int, int, tuple[str, str]]]] = {title: [] for title in self.titles()}
        for at, param in enumerate(self.get_params(ctx)):
            record = param.get_help_record(ctx)
            if record is not None:
                title, rank = place_of(param.name or "", self.sections)
                rows[title].append((rank, at, record))
        for title, records in rows.items():
            if records:
                with formatter.section(title):
                    formatter.write_dl([record for *_, record in sorted(records)])


class WorkflowGroup(click.Group):
    """The ``sdnn`` group: ``sdnn --help`` lists the commands in the order of a first session (check, build,
    simulate, identify, inspect, diagnose, scale out), not alphabetically; a command not in `order` comes last."""

    def __init__(self, *args, order: tuple[str, ...] = (), **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.order = tuple(order)

    def list_commands(self, ctx: click.Context) -> list[str]:
        rank = {name: i for i, name in enumerate(self.order)}
        return sorted(self.commands, key=lambda name: (rank.get(name, len(rank)), name))
