"""Building hosted nodes: a robot's nodes from the world file with the options of their own
process (``nodes.py``, ``node_options.py``), checked against the topic contract (``wiring.py``);
lifecycle nodes brought up (``lifecycle.py``)."""
