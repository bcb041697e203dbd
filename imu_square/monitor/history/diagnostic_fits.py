"""Each night's diagnostics, two tables of the history: the fit, and its diagnostics.

A fit is stored once per run and diagnostic settings (effects, shapes,
software: :meth:`~imu_square.monitor.diagnostics.settings.DiagnosticSettings.key`),
with the night's run in the same transaction, and never rewritten: a
replay under other diagnostic settings adds fits beside the old ones.
"""

import json
from dataclasses import replace

from imu_square.errors import HistoryError
from imu_square.monitor.history.encoding import canonical_json
from imu_square.monitor.history.rows import DiagnosticFitRow, DiagnosticRow
from imu_square.monitor.history.sql import Table

DIAGNOSTIC_FITS = Table("diagnostic_fits", DiagnosticFitRow, skip=("values",))
DIAGNOSTICS = Table("diagnostics", DiagnosticRow)


class DiagnosticFits:
    """The diagnostics' methods of :class:`~imu_square.monitor.history.store.History`."""

    def add_diagnostic_fit(self, row):
        """Store a night's diagnostic fit and its diagnostics, once per (run, settings).

        Parameters
        ----------
        row : DiagnosticFitRow
            The fit, its ``run_id`` set; ``id`` is ignored, ``fitted_at_ns``
            stamped if None.

        Returns
        -------
        fit_id : int
            The fit's row.
        inserted : bool
            False when the run had a fit under these settings already: that
            one is kept as it was.
        """
        if not isinstance(row, DiagnosticFitRow):
            raise HistoryError(
                f"add_diagnostic_fit needs a DiagnosticFitRow, got {type(row).__name__}"
            )
        if row.run_id is None:
            raise HistoryError("DiagnosticFitRow.run_id must name the run it was fitted to")
        values = DIAGNOSTIC_FITS.values(row, stamp="fitted_at_ns")
        with self._write():
            self.run(row.run_id)  # one line naming a run that is not there
            got = self._insert(
                DIAGNOSTIC_FITS, values, "ON CONFLICT (run_id, settings_hash) DO NOTHING"
            )
            if not got:
                p = self._params()
                found = self._conn.query(
                    f"SELECT id FROM diagnostic_fits WHERE run_id = {p(row.run_id)} "
                    f"AND settings_hash = {p(row.settings_hash)}",
                    p.values,
                )
                return found[0][0], False
            fit_id = got[0][0]
            for v in row.values:
                self._insert(DIAGNOSTICS, DIAGNOSTICS.values(v) | {"fit_id": fit_id})
        return fit_id, True

    def diagnostic_fits(self, machine_id, settings_hash):
        """A machine's fits under some diagnostic settings, by run.

        Parameters
        ----------
        machine_id : str
            The machine.
        settings_hash : str
            :meth:`~imu_square.monitor.diagnostics.settings.DiagnosticSettings.key`.

        Returns
        -------
        dict of int to DiagnosticFitRow
            Run id to its fit, with its diagnostics.
        """
        p = self._params()
        where = self._fits_of(machine_id, settings_hash, p)
        with self._read():
            fits = self._select(DIAGNOSTIC_FITS, f"diagnostic_fits.id IN ({where})", p)
            p = self._params()
            where = self._fits_of(machine_id, settings_hash, p)
            rows = self._select(DIAGNOSTICS, f"fit_id IN ({where})", p, "fit_id, id")
        by_fit = {}
        for r in rows:
            by_fit.setdefault(r.fit_id, []).append(r)
        return {f.run_id: replace(f, values=tuple(by_fit.get(f.id, ()))) for f in fits}

    def diagnostic_settings(self, machine_id):
        """Every set of diagnostic settings a machine's fits were made under.

        Parameters
        ----------
        machine_id : str
            The machine.

        Returns
        -------
        dict of str to dict
            Settings hash to the settings (JSON values), oldest fit's first.
        """
        p = self._params()
        sql = (
            "SELECT diagnostic_fits.settings_hash, MIN(diagnostic_fits.settings_json), "
            "MIN(diagnostic_fits.id) AS first_id FROM diagnostic_fits JOIN runs ON runs.id = "
            f"diagnostic_fits.run_id WHERE runs.machine_id = {p(machine_id)} "
            "GROUP BY diagnostic_fits.settings_hash ORDER BY first_id"
        )
        with self._read():
            rows = self._conn.query(sql, p.values)
        return {h: json.loads(text) for h, text, _ in rows}

    def _fits_of(self, machine_id, settings_hash, p):
        """The ids of a machine's fits under some settings, as a sub-query."""
        return (
            "SELECT diagnostic_fits.id FROM diagnostic_fits JOIN runs ON runs.id = "
            f"diagnostic_fits.run_id WHERE runs.machine_id = {p(machine_id)} AND "
            f"diagnostic_fits.settings_hash = {p(settings_hash)}"
        )

    def diagnosed_hashes(self, machine_id, settings_hash, diagnostics_hash):
        """SHA-256 of the recordings stored with all they need: an invalid run, or a valid
        one with a diagnostic fit under these settings.

        A replay skips these; a recording whose valid run is stored without
        such a fit is read again for its diagnostics.

        Parameters
        ----------
        machine_id : str
            The machine.
        settings_hash : str
            The runs' analysis settings.
        diagnostics_hash : str
            The diagnostic settings.

        Returns
        -------
        set of str
        """
        p = self._params()
        sql = (
            "SELECT runs.recording_sha256 FROM runs LEFT JOIN diagnostic_fits ON "
            "diagnostic_fits.run_id = runs.id AND diagnostic_fits.settings_hash = "
            f"{p(diagnostics_hash)} WHERE runs.machine_id = {p(machine_id)} AND "
            f"runs.settings_hash = {p(settings_hash)} AND "
            f"(runs.valid = {p(False)} OR diagnostic_fits.id IS NOT NULL)"
        )
        return {r[0] for r in self._conn.query(sql, p.values)}

    def set_diagnostic_designs(self, baseline_id, designs):
        """Keep the alarm designs of a baseline's diagnostics (made once, read every night).

        Parameters
        ----------
        baseline_id : int
            The baseline.
        designs : dict
            Diagnostic name to its design (JSON values).
        """
        p = self._params()
        text = canonical_json(designs, "diagnostic designs")
        sql = (
            f"UPDATE baselines SET diagnostic_designs_json = {p(text)} WHERE id = {p(baseline_id)}"
        )
        with self._write():
            if not self._conn.execute(sql, p.values):
                self._require("baselines", baseline_id, "baseline")
