"""The tutorial as a book: the notebooks (executed, or as committed) built by
Sphinx with myst-nb and sphinx-book-theme into pages that open from disk
(:func:`build_site`, ``python -m helpers site``). It needs a checkout: the
notebooks are not shipped in the package."""

from helpers.site.build import build_site, notebook_paths, solution_paths

__all__ = ["build_site", "notebook_paths", "solution_paths"]
