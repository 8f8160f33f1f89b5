"""The storage interface: what a backend (SQLite today, PostgreSQL/PostGIS later) provides.

All reads and writes happen inside ``store.transaction()``; a backend commits the whole
block or nothing, so a crash, a kill or an exception in the middle never leaves half a
change behind. Write transactions are serialised (SQLite: ``BEGIN IMMEDIATE``), so code
running inside one may read, decide and write without races.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from contextlib import AbstractContextManager

from gsgeo.store.records import CheckPointRecord, FeatureRecord, PointRecord, Project


class Transaction(ABC):
    """One atomic unit of work on the store."""

    # projects
    @abstractmethod
    def list_projects(self) -> list[Project]: ...
    @abstractmethod
    def get_project(self, pid: str) -> Project | None: ...
    @abstractmethod
    def insert_project(self, project: Project) -> None: ...
    @abstractmethod
    def update_project(self, project: Project) -> None: ...
    @abstractmethod
    def delete_project(self, pid: str) -> bool: ...

    # points
    @abstractmethod
    def list_points(self, pid: str, results: bool = True) -> list[PointRecord]:
        """The project's points in creation order; ``results=False`` leaves their stored
        results unread (None), for callers that are about to measure them again."""
    @abstractmethod
    def get_point(self, pid: str, point_id: str) -> PointRecord | None: ...
    @abstractmethod
    def point_ids(self, pid: str) -> list[str]: ...
    @abstractmethod
    def insert_point(self, point: PointRecord) -> None: ...
    @abstractmethod
    def update_point(self, point: PointRecord, old_id: str | None = None) -> None:
        """Write ``point``; ``old_id`` is its previous id when it is being renamed."""
    @abstractmethod
    def delete_point(self, pid: str, point_id: str) -> bool: ...

    # lines and polygons
    @abstractmethod
    def list_features(self, pid: str, kind: str) -> list[FeatureRecord]: ...
    @abstractmethod
    def get_feature(self, pid: str, kind: str, fid: str) -> FeatureRecord | None: ...
    @abstractmethod
    def insert_feature(self, feature: FeatureRecord) -> None: ...
    @abstractmethod
    def update_feature(self, feature: FeatureRecord, old_id: str | None = None) -> None: ...
    @abstractmethod
    def delete_feature(self, pid: str, kind: str, fid: str) -> bool: ...

    # check points
    @abstractmethod
    def list_check_points(self, pid: str) -> list[CheckPointRecord]: ...
    @abstractmethod
    def upsert_check_points(self, records: list[CheckPointRecord]) -> None: ...
    @abstractmethod
    def delete_check_point(self, pid: str, cid: str) -> bool: ...
    @abstractmethod
    def delete_all_check_points(self, pid: str) -> int: ...


class Store(ABC):
    """A place where projects live."""

    @abstractmethod
    def transaction(self, write: bool = True) -> AbstractContextManager[Transaction]:
        """Context manager: the block's reads and writes commit together or not at all."""

    @abstractmethod
    def close(self) -> None: ...

    @abstractmethod
    def check_integrity(self) -> list[str]:
        """Problems found in the stored data (empty when sound)."""

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


