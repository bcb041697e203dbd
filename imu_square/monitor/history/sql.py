"""The SQL the store writes: a table's rows as columns, and parameters in the backend's style.

A :class:`Table` maps a row dataclass (:mod:`~imu_square.monitor.history.rows`)
to its table: one column per field, of the field's name, except that a
field annotated ``dict`` or ``tuple`` holds JSON and is stored as canonical
JSON text in the column ``NAME_json``. Rows read back through
:func:`~imu_square.json_values.from_json`, which gives each field its
annotated type (SQLite's 0/1 become booleans, JSON lists tuples).

:class:`Params` collects a statement's parameters and writes each one's
marker in the backend's own style (SQLite's ``?``, PostgreSQL's ``$1``,
``$2``...), so that the SQL text itself is never rewritten: a literal ``?``
or ``%`` in it means what it says on both backends.
"""

import json
from dataclasses import fields

from imu_square.json_values import from_json
from imu_square.monitor.history.encoding import canonical_json, now_ns


class Table:
    """How the rows of one dataclass are stored in one table.

    Parameters
    ----------
    name : str
        The table.
    row : type
        The row dataclass.
    skip : tuple of str
        Fields kept in another table.
    """

    def __init__(self, name, row, skip=()):
        self.name = name
        self.row = row
        kept = [f for f in fields(row) if f.name not in skip]
        self.fields = [f.name for f in kept]
        self.json = {f.name for f in kept if f.type in (dict, tuple)}
        self.columns = [f"{n}_json" if n in self.json else n for n in self.fields]

    def values(self, row, stamp=None):
        """The row's values by column, JSON fields as text, without the id.

        Parameters
        ----------
        row : dataclass
            A row of :attr:`row`.
        stamp : str, optional
            A time field that gets the time now when the row leaves it None.

        Returns
        -------
        dict
            Column name to value.
        """
        out = {}
        for name, column in zip(self.fields, self.columns, strict=True):
            value = getattr(row, name)
            if name in self.json:
                value = canonical_json(value, f"{self.row.__name__}.{name}")
            elif name == stamp and value is None:
                value = now_ns()
            if name != "id":
                out[column] = value
        return out

    def read(self, values, **more):
        """A row from its columns' values, in :attr:`columns` order (``more``: skipped fields)."""
        kw = {
            n: json.loads(v) if n in self.json else v
            for n, v in zip(self.fields, values, strict=True)
        }
        return from_json(self.row, kw | more)


class Params:
    """A statement's parameters, each written as a marker in the backend's style.

    >>> p = Params(backend.mark)  # doctest: +SKIP
    >>> backend.query(f"SELECT id FROM runs WHERE machine_id = {p(machine)}", p.values)

    Parameters
    ----------
    mark : callable
        ``mark(i)``: the backend's marker of the ``i``-th parameter (from 1).
    """

    def __init__(self, mark):
        self._mark = mark
        self.values = []

    def __call__(self, value):
        """Add ``value``; return its marker."""
        self.values.append(value)
        return self._mark(len(self.values))

    def list(self, values):
        """Add each of ``values``; return their markers, comma-separated."""
        return ", ".join(self(v) for v in values)
