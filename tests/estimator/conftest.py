"""The estimator's tests mirror ``estimator/``; this file's folder holds helpers shared across
its subfolders (``_synthetic_drive``), which pytest makes importable by loading it."""
