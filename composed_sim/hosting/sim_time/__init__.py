"""The hosted nodes' time: their timers fired at a defined point of each tick (``timers.py``), their
rates and clock sleeps set aside on sim time (``sleeps.py``)."""
