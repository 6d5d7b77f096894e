"""The journal: every accepted event and every step, durable in SQLite; resume and replay.

See docs/journal.md. :class:`Journal` writes (one thread, group commit),
:class:`JournalReader` reads, :class:`JournalledDevice` binds a running Subject
to both, :func:`load_device` reads a device file with its Recovery table.
"""

from statectl.run.journal.check import JournalDamaged, check_journal, set_aside
from statectl.run.journal.device import JournalledDevice
from statectl.run.journal.device_file import DeviceFile, RecoveryRule, load_device
from statectl.run.journal.format import Guarantee, JournalError, StepKind, Sync
from statectl.run.journal.read import (
    ACKNOWLEDGED,
    REDO,
    REFUSED,
    DeviceRow,
    InboxRow,
    JournalReader,
    Mismatch,
    ReplayResult,
    StepRow,
    export_jsonl,
    replay,
)
from statectl.run.journal.store import Journal, Ticket
from statectl.run.journal.subjects import restore_subject

__all__ = [
    "ACKNOWLEDGED",
    "REDO",
    "REFUSED",
    "DeviceFile",
    "DeviceRow",
    "Guarantee",
    "InboxRow",
    "Journal",
    "JournalDamaged",
    "JournalError",
    "JournalReader",
    "JournalledDevice",
    "Mismatch",
    "RecoveryRule",
    "ReplayResult",
    "StepKind",
    "StepRow",
    "Sync",
    "Ticket",
    "check_journal",
    "export_jsonl",
    "load_device",
    "replay",
    "restore_subject",
    "set_aside",
]
