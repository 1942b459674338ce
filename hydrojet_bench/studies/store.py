"""Where a study's (or a batch's) rows go: one Parquet part file per finished row under
``DIR/rows/``, written to a temporary name and renamed, so a killed study never leaves
a half-written row and a rerun knows exactly which ids are done.
"""

from __future__ import annotations

import os
from collections.abc import Collection, Mapping
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ..errors import UserError


class RowStore:
    """Rows keyed by ``id_column``, each in ``DIR/rows/<id>.parquet``; ``columns`` maps
    every column to a pyarrow type name ("string", "float64", "int64", "bool")."""

    def __init__(self, folder: Path, columns: Mapping[str, str], id_column: str) -> None:
        self.folder = Path(folder)
        self.rows_folder = self.folder / "rows"
        self.schema = pa.schema([(name, pa.type_for_alias(kind)) for name, kind in columns.items()])
        self.id_column = id_column
        try:
            self.rows_folder.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise UserError(f"{self.folder}: cannot create the result folder: {error.strerror or error}") from None

    def finished(self) -> set[str]:
        """Ids of the rows already stored."""
        return {path.stem for path in self.rows_folder.glob("*.parquet")}

    def append(self, row: Mapping[str, object]) -> Path:
        """Store one row at once (atomically: a temporary file renamed into place)."""
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
        return pa.concat_tables(pq.read_table(part, schema=self.schema) for part in parts).to_pandas()

    def write_csv(self, ids: Collection[str] | None = None) -> Path:
        """The table (of ``ids`` when given) as ``DIR/rows.csv`` beside the Parquet parts."""
        path = self.folder / "rows.csv"
        self.table(ids).to_csv(path, index=False)
        return path
