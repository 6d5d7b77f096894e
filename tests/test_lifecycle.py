"""How ``statectl run`` and ``statectl node`` end (channels/cli/lifecycle.py rule 3)."""

from __future__ import annotations

import io

import pytest

from statectl.channels.cli.lifecycle import Ending
from statectl.run.journal import JournalError


class _FailingClose:
    """A System whose journal fails as it closes (a disk gone full under the writer)."""

    def __init__(self) -> None:
        self.closed = 0

    def close(self) -> None:
        self.closed += 1
        raise JournalError("journal j.db: database or disk is full")


@pytest.mark.parametrize("command", ["run", "node"])
@pytest.mark.parametrize("said_before", [False, True])
def test_a_journal_failure_at_close_is_said_once_by_the_command_that_ran(
    command: str, said_before: bool
) -> None:
    """The close's journal failure names the command the user ran (a node said
    ``statectl run:``), and is not said again when the command already said it."""
    err = io.StringIO()
    ending = Ending(command, err)
    system = _FailingClose()
    ending.system = system  # type: ignore[assignment]  # only close() is called
    if said_before:
        ending.fail(JournalError("journal j.db: database or disk is full"))
    ending.close()
    assert system.closed == 1
    assert err.getvalue() == f"statectl {command}: journal j.db: database or disk is full\n"
