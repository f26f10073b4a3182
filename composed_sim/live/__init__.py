"""Watching a run while it runs: the tick observers (``observers.py``: the recording's, the
markers'), the scene as one MarkerArray (``markers.py``), the Foxglove server
(``foxglove_server.py``) and pacing to a rate of real time (``pacing.py``)."""

DEFAULT_FOXGLOVE_HOST, DEFAULT_FOXGLOVE_PORT = "127.0.0.1", 8765     # --foxglove without an address
