"""Running devices: the runtime, drivers, the journal and the System that owns them.

``runtime`` (the Subject: queue, clock, observers, monitors, timers), ``devices``
(drivers and simulated twins), ``journal`` (the SQLite journal, recovery, shipping),
``system`` (many devices and a cell's links on one owner) and ``runner`` (event lines
and cell setups, for the channels).
"""
