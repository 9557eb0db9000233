"""Reading and writing what routefuse works on: logs (through the registry of log formats),
route files, and routes built from a drive. This is the package's public face.

Importing it stays light (no numpy, no pyproj, no rosbags) so that the CLI's parser can take the
formats' wording from :data:`LOG_FORMATS_TEXT`; the names of the heavier modules (decode cache,
route files, route building, bag writing) are imported on first use."""

from __future__ import annotations

from typing import TYPE_CHECKING

from estimator._lazy import lazy_getattr
from estimator.io.registry import (
    LOG_FORMATS,
    LOG_FORMATS_TEXT,
    LOG_SUFFIXES_TEXT,
    LogReader,
    describe_topics,
    is_log_path,
    load_log,
    log_suffixes,
    open_log_path,
)
from estimator.io.routeformats import (
    ROUTE_FORMATS,
    ROUTE_FORMATS_TEXT,
    ROUTE_SUFFIXES_TEXT,
    is_route_path,
    route_beside,
    route_format,
)
from estimator.io.topics import AUTO_TOPICS, TopicChoice, TopicRoles, is_truth_topic

if TYPE_CHECKING:
    from estimator.io.bagwrite import BagTopics, StaticTransform, write_bag
    from estimator.io.cache import CACHE_VERSION, default_cache_dir
    from estimator.io.routebuild import route_from_gnss, route_geojson
    from estimator.io.routefile import (
        RouteLine,
        load_route,
        read_route_file,
        read_route_lines,
        route_in_frame,
    )

_LAZY = {
    "CACHE_VERSION": "estimator.io.cache",
    "default_cache_dir": "estimator.io.cache",
    "BagTopics": "estimator.io.bagwrite",
    "StaticTransform": "estimator.io.bagwrite",
    "write_bag": "estimator.io.bagwrite",
    "route_from_gnss": "estimator.io.routebuild",
    "route_geojson": "estimator.io.routebuild",
    "RouteLine": "estimator.io.routefile",
    "load_route": "estimator.io.routefile",
    "read_route_file": "estimator.io.routefile",
    "read_route_lines": "estimator.io.routefile",
    "route_in_frame": "estimator.io.routefile",
}

__all__ = [
    "AUTO_TOPICS",
    "CACHE_VERSION",
    "LOG_FORMATS",
    "LOG_FORMATS_TEXT",
    "LOG_SUFFIXES_TEXT",
    "ROUTE_FORMATS",
    "ROUTE_FORMATS_TEXT",
    "ROUTE_SUFFIXES_TEXT",
    "BagTopics",
    "LogReader",
    "RouteLine",
    "StaticTransform",
    "TopicChoice",
    "TopicRoles",
    "default_cache_dir",
    "describe_topics",
    "is_log_path",
    "is_route_path",
    "is_truth_topic",
    "load_log",
    "load_route",
    "log_suffixes",
    "open_log_path",
    "read_route_file",
    "read_route_lines",
    "route_beside",
    "route_format",
    "route_from_gnss",
    "route_geojson",
    "route_in_frame",
    "write_bag",
]


__getattr__ = lazy_getattr(__name__, _LAZY)
