"""The one progress bar of the package (tqdm; plain text outside notebooks)."""


def progress_bar(total: int, what: str):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=what, unit="scan", leave=False)
