"""The views: text, HTML pages and figures of every command, drawn from typed results only.

Computation (identify/, diagnose/, batch/, ...) never draws and never imports this package; the command line
and the public API call it. Modules:

* :mod:`.identify_text`, :mod:`.diagnose_text`: what the commands print (pure functions of the results)
* :mod:`.html`: the pieces of a self-contained page; :mod:`.identify_page` (its tables in
  :mod:`.identify_tables`), :mod:`.diagnose_page` the pages; :mod:`.linear` the linearised chart they read
* :mod:`.canvas`: one figure on its own Agg canvas (no pyplot), PNG bytes written atomically
* :mod:`.figures` (compare, residual analysis), :mod:`.bode`, :mod:`.identify_plots`, :mod:`.diagnose_plots`,
  :mod:`.drift` (the fleet report): the figures
* :mod:`.notebook`: what a notebook shows of an identification or a diagnosis (one line, a short text, an HTML
  fragment)

Importing the package is cheap (matplotlib and the modules above load on first use); it registers the
drawing that ``Identification.compare(plot=)`` delegates to and the notebook views (``repr``, ``summary()``,
``_repr_html_``) of identifications and diagnoses (:mod:`.notebook`), through :mod:`flowchart2sdnn.views`.

Layer: above every computation package, below the API and the command line.
"""

from __future__ import annotations

from ..views import register


def _compare_png(comparison, path, name: str = ""):
    """:func:`.figures.write_compare`, loaded on first use: `import flowchart2sdnn` must not pay for it."""
    from .figures import write_compare

    return write_compare(comparison, path, name)


register("compare_png", _compare_png)


def _notebook(name: str):
    """A view of :mod:`.notebook` (repr, summary(), _repr_html_ of the results), loaded on first use."""
    def draw(*args, **kwargs):
        from . import notebook

        return getattr(notebook, name)(*args, **kwargs)
    return draw


for _name in ("identification_line", "identification_text", "identification_html", "diagnosis_line",
              "diagnosis_text", "diagnosis_html"):
    register(_name, _notebook(_name))
