"""The command line (``python -m helpers``), its output folders, and the notebooks' cached run."""
