"""The inspector's tests mirror ``inspector/``; this file's folder holds the fake runs shared
across its subfolders (``fake_runs``), which pytest makes importable by loading it."""
