"""The one progress bar of the package (tqdm; plain text outside notebooks)."""


def progress_bar(total: int, what: str, enabled: bool = True):
    """A bar over ``total`` scans labelled ``what``; with ``enabled=False`` a
    silent one (tqdm's ``disable``) whose ``update`` and ``close`` do nothing."""
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=what, unit="scan", leave=False, disable=not enabled)
