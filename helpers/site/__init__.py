"""The static site: the notebooks executed and exported to HTML that opens
from disk (:func:`build_site`, ``python -m helpers site``), with its page
template in ``templates/``. It needs a checkout: the notebooks are not shipped
in the package."""

from .build import build_site, notebook_paths

__all__ = ["build_site", "notebook_paths"]
