"""The Tunnel de Monaco (A 500, direction 1) as OpenStreetMap maps it: the road the
``monaco_tunnel`` scenario drives.

Map data (c) OpenStreetMap contributors, available under the Open Database License (ODbL)
v1.0, https://www.openstreetmap.org/copyright . These vertices are feature 0 of
``shared/data/osm_monaco/monaco_tunnels.geojson`` (a Derived Database of the OSM extract
``test/data/monaco.osm.pbf`` of github.com/Project-OSRM/osrm-backend, replication timestamp
2016-03-05), copied unchanged; they and every file derived from them (the ``monaco_tunnel``
sample log and route) are likewise ODbL 1.0: keep ``sample_logs/ATTRIBUTION`` next to them.

OSM ways: Moyenne Corniche, Bretelle de Monaco, Tunnel de Monaco (way 156615621), A 500.
The raw vertex sequence is kept: segments up to 512 m, with the curvature at the vertices.
"""

ATTRIBUTION = (
    "Map data (c) OpenStreetMap contributors, ODbL 1.0 "
    "(https://www.openstreetmap.org/copyright); Tunnel de Monaco geometry from "
    "monaco.osm.pbf of github.com/Project-OSRM/osrm-backend (2016-03-05)"
)

TUNNEL_START_VERTEX = 10
TUNNEL_END_VERTEX = 20

LONLAT: tuple[tuple[float, float], ...] = (
    (7.3904887, 43.7325763),
    (7.3903696, 43.7327242),
    (7.3902099, 43.7328732),
    (7.3899521, 43.7329962),
    (7.389686, 43.7330797),
    (7.3888606, 43.7332217),
    (7.3885584, 43.7332733),
    (7.3881668, 43.7333794),
    (7.3879617, 43.7334651),
    (7.3876076, 43.7336516),
    (7.3872013, 43.7339053),
    (7.3867964, 43.7342339),
    (7.386236, 43.7347733),
    (7.3854536, 43.7361005),
    (7.3846506, 43.7389656),
    (7.3835262, 43.7435047),
    (7.3830026, 43.7444286),
    (7.3822645, 43.7451541),
    (7.3813719, 43.745892),
    (7.3805908, 43.7461772),
    (7.3796006, 43.7463615),
    (7.379355, 43.7463973),
    (7.3791814, 43.7464234),
    (7.3790514, 43.7464316),
    (7.3789026, 43.7464326),
    (7.3786478, 43.7464142),
    (7.3784613, 43.7463909),
    (7.3780226, 43.7462672),
    (7.3776894, 43.7461417),
    (7.3775306, 43.7460693),
    (7.3773831, 43.7459831),
    (7.3772074, 43.7458581),
    (7.3770384, 43.7457283),
    (7.376742, 43.7454647),
    (7.3765637, 43.7453281),
    (7.376388, 43.7452022),
)
"""(lon, lat) WGS84 vertices in driving order."""
