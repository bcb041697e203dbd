"""The alert outbox, a table of the history: each night's alert for each sink, until delivered.

A night's alerts are written in the same transaction as its run and verdict
(:func:`~imu_square.monitor.night.judge_recording`), so a night is stored
with its pending alerts or not at all; they are sent after the commit
(:mod:`imu_square.monitor.alerts.send`). A row is ``pending`` until a sink
takes it (``delivered``, kept as a log) or refuses it as a configuration
error (``rejected``, kept and not retried until it is queued again).

Two processes may deliver at once. A delivery round *claims* a pending row
before it tries the sink: one UPDATE that sets ``claimed_by`` and
``claimed_until_ns`` only where no live claim holds the row. On SQLite the
writers take turns; on PostgreSQL the second UPDATE of a row waits for the
first to commit and then no longer matches. Either way one round wins and
the alert is sent once. The round then settles the row, only while its own
claim holds it. A process killed mid-delivery leaves its claim behind: when
the claim runs out, the next round takes the row again (delivery is at least
once; receivers dedupe on the alert's id).
"""

from imu_square.monitor.history.encoding import now_ns
from imu_square.monitor.history.rows import OutboxRow
from imu_square.monitor.history.sql import Table

OUTBOX = Table("outbox", OutboxRow)


class Outbox:
    """The outbox's methods of :class:`~imu_square.monitor.history.store.History`."""

    def add_alert(self, row):
        """Keep an alert for one sink in the outbox.

        Parameters
        ----------
        row : OutboxRow
            The alert; its ``id`` is ignored, ``updated_at_ns`` is stamped if None.

        Returns
        -------
        int
            The row's id.
        """
        with self._write():
            return self._insert(OUTBOX, OUTBOX.values(row, stamp="updated_at_ns"))[0][0]

    def outbox(self, machine_id, state="pending"):
        """A machine's alerts in one state, oldest first.

        Parameters
        ----------
        machine_id : str
            The machine.
        state : str
            ``"pending"``, ``"delivered"`` or ``"rejected"``.

        Returns
        -------
        list of OutboxRow
        """
        p = self._params()
        where = f"machine_id = {p(machine_id)} AND state = {p(state)}"
        return self._select(OUTBOX, where, p, "created_at_ns, id")

    def claim_alert(self, row_id, claim, until_ns, at_ns=None):
        """Take a pending alert until ``until_ns``, unless a claim holds it at ``at_ns``.

        Parameters
        ----------
        row_id : int
            The alert's row.
        claim : str
            The delivery round's own random token.
        until_ns : int
            When the claim runs out. [ns]
        at_ns : int, optional
            The time now. [ns]

        Returns
        -------
        bool
            True if this round now holds the alert.
        """
        p = self._params()
        sql = (
            f"UPDATE outbox SET claimed_by = {p(claim)}, claimed_until_ns = {p(until_ns)} "
            f"WHERE id = {p(row_id)} AND state = 'pending' AND (claimed_until_ns IS NULL "
            f"OR claimed_until_ns <= {p(now_ns() if at_ns is None else at_ns)})"
        )
        with self._write():
            return self._conn.execute(sql, p.values) == 1

    def settle_alert(self, row_id, claim, state, attempts, last_error):
        """Record a round's tries of a claimed alert, and release it.

        Parameters
        ----------
        row_id : int
            The alert's row.
        claim : str
            The token it was claimed with.
        state : str
            ``"pending"``, ``"delivered"`` or ``"rejected"``.
        attempts : int
            Tries in this round.
        last_error : str or None
            The last failure.

        Returns
        -------
        bool
            False if the claim had run out and another round took the alert
            (nothing is changed then).
        """
        p = self._params()
        sql = (
            f"UPDATE outbox SET state = {p(state)}, attempts = attempts + {p(attempts)}, "
            f"last_error = {p(last_error)}, claimed_by = NULL, claimed_until_ns = NULL, "
            f"updated_at_ns = {p(now_ns())} WHERE id = {p(row_id)} AND claimed_by = {p(claim)}"
        )
        with self._write():
            return self._conn.execute(sql, p.values) == 1

    def requeue_rejected(self, machine_id):
        """Make a machine's rejected alerts pending again (the monitor file is fixed).

        Parameters
        ----------
        machine_id : str
            The machine.

        Returns
        -------
        int
            Number of alerts queued again.
        """
        p = self._params()
        sql = (
            f"UPDATE outbox SET state = 'pending', updated_at_ns = {p(now_ns())} "
            f"WHERE machine_id = {p(machine_id)} AND state = 'rejected'"
        )
        with self._write():
            return self._conn.execute(sql, p.values)
