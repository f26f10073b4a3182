"""What the host keeps of each node's conduct: a faulty or hung callback is its robot's fault
(``callback_guard.py``), its log lines and tracebacks (``node_logs.py``), the CPU time of its own
code (``node_time.py``)."""
