"""Packaging beyond what pyproject.toml can say: the bundled sample logs (``sample_logs/`` at the
top of the repository, with their ATTRIBUTION) are installed as the package data of
``inspector.sample_logs``, so that ``routefuse serve`` finds them in a non-editable install too
(:mod:`inspector.cli.samples`); and the replay page's panel (a Jinja2 template and its script,
read with importlib.resources). Everything else is in pyproject.toml."""

from setuptools import find_packages, setup

SAMPLES = "inspector.sample_logs"
SAMPLE_FILES = ["*.mcap", "*.geojson", "ATTRIBUTION", "README.md", "configs/*.toml"]

setup(
    packages=[*find_packages(include=["estimator*", "inspector*"]), SAMPLES],
    package_dir={SAMPLES: "sample_logs"},
    package_data={SAMPLES: SAMPLE_FILES, "inspector.export": ["templates/*"]},
)
