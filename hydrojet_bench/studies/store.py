"""Where a study's (or a batch's) rows go: one Parquet part file per finished row under
``DIR/rows/``, written to a temporary name and renamed, so a killed study never leaves
a half-written row and a rerun knows exactly which ids are done.
"""

from __future__ import annotations

import json
import os
from collections.abc import Collection, Mapping
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ..errors import UserError

# The spec last run into the folder (its resolved path) and the ids of its cells.
MEMBERS_FILE = "members.json"


class RowStore:
    """Rows keyed by ``id_column``, each in ``DIR/rows/<id>.parquet``; ``columns`` maps
    every column to a pyarrow type name ("string", "float64", "int64", "bool")."""

    def __init__(self, folder: Path, columns: Mapping[str, str], id_column: str) -> None:
        self.folder = Path(folder)
        self.rows_folder = self.folder / "rows"
        self.schema = pa.schema([(name, pa.type_for_alias(kind)) for name, kind in columns.items()])
        self.id_column = id_column

    def create(self) -> None:
        """Make the folder (nothing is written before: a folder refused stays as it was)."""
        try:
            self.rows_folder.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise UserError(f"{self.folder}: cannot create the result folder: {error.strerror or error}") from None

    def claim(self, spec: str, ids: Collection[str]) -> None:
        """Make the folder the results of ``spec`` (an identity: its resolved path) with
        cells ``ids``, kept as the folder's members: what a later `members` (a report
        rebuilt without the spec) takes as its rows. Refused, before anything is written,
        for a folder of another kind's rows, or of another spec's study (its members and
        report would be replaced, its rows then called left out): one whose cells neither
        include nor are included in ``ids``, as a copy's or a narrowed or widened spec's are."""
        self.check_kind()
        recorded = self._recorded()
        if recorded is not None and recorded[0] not in (None, spec) and \
                not (recorded[1] <= set(ids) or set(ids) <= recorded[1]):
            raise UserError(f"{self.folder}: holds the study of {recorded[0]} ({len(recorded[1])} cells), not of "
                            f"{spec}; give another folder, or run that spec into it")
        self.create()
        (self.folder / MEMBERS_FILE).write_text(json.dumps({"spec": spec, "cells": sorted(ids)}))

    def members(self) -> set[str] | None:
        """The ids the last `claim` kept (None when it never ran here)."""
        recorded = self._recorded()
        return None if recorded is None else recorded[1]

    def _recorded(self) -> tuple[str | None, set[str]] | None:
        """(spec, cell ids) of the last `claim`; the spec is None in a folder written
        before members named it."""
        path = self.folder / MEMBERS_FILE
        try:
            document = json.loads(path.read_text())
            if isinstance(document, list):
                return None, set(document)
            return str(document["spec"]), set(document["cells"])
        except FileNotFoundError:
            return None
        except (OSError, ValueError, TypeError, KeyError) as error:
            raise UserError(f"{path}: unreadable ({error}); remove it to report every stored row") from None

    def check_kind(self) -> None:
        """Refuse a folder holding rows of another kind (`_read`'s words), from one of them."""
        first = next(iter(sorted(self.rows_folder.glob("*.parquet"))), None)
        if first is not None:
            self._read(first)

    def stored(self) -> set[str]:
        """Ids of the rows stored, failed ones included."""
        return {path.stem for path in self.rows_folder.glob("*.parquet")}

    def finished(self) -> set[str]:
        """Ids of the rows stored without an error (a rerun tries the failed ones again)."""
        table = self.table()
        return set(table.loc[table["error"].isna(), self.id_column]) if "error" in table else set(table[self.id_column])

    def append(self, row: Mapping[str, object]) -> Path:
        """Store one row at once (atomically: a temporary file renamed into place)."""
        if not self.rows_folder.is_dir():
            self.create()
        path = self.rows_folder / f"{row[self.id_column]}.parquet"
        temporary = path.with_suffix(".tmp")
        pq.write_table(pa.Table.from_pylist([dict(row)], schema=self.schema), temporary)
        os.replace(temporary, path)
        return path

    def table(self, ids: Collection[str] | None = None) -> pd.DataFrame:
        """The stored rows (only those of ``ids`` when given), one pandas table (empty with
        the columns when none is)."""
        parts = sorted(path for path in self.rows_folder.glob("*.parquet") if ids is None or path.stem in ids)
        if not parts:
            return self.schema.empty_table().to_pandas()
        return pa.concat_tables(self._read(part) for part in parts).to_pandas()

    def _read(self, part: Path) -> pa.Table:
        try:
            table = pq.read_table(part)
            if table.schema.names == self.schema.names:
                return table.cast(self.schema)
            if self.id_column in table.schema.names and set(table.schema.names) < set(self.schema.names):
                # A row stored before its kind gained columns: kept, the new figures empty.
                return pa.Table.from_pylist(table.to_pylist(), schema=self.schema)
        except (pa.ArrowException, OSError) as error:
            raise UserError(f"{part}: not a readable row ({error}); remove it, or give another folder") from None
        raise UserError(f"{part}: a row of another kind (columns {', '.join(table.schema.names[:3])}, ...): this "
                        "folder holds another command's results; give another folder")

    def write_csv(self, ids: Collection[str] | None = None) -> Path:
        """The table (of ``ids`` when given) as ``DIR/rows.csv`` beside the Parquet parts."""
        path = self.folder / "rows.csv"
        self.table(ids).to_csv(path, index=False)
        return path
