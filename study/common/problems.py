"""Problems of a study folder: one :class:`Problem` (file, line, field, message), the list that collects them while a
study is checked (:class:`Problems`), and :class:`StudyError`, which names the first of them."""
from __future__ import annotations

from dataclasses import dataclass

from study.common.errors import UserError


class StudyError(UserError):
    """A study folder (or stored definition) with problems; ``problems`` lists all of them."""

    def __init__(self, problems: list["Problem"]):
        self.problems = problems
        more = f" (and {len(problems) - 1} more problem(s); run `pedas-study study check`)" if len(problems) > 1 else ""
        super().__init__(f"{problems[0]}{more}")


@dataclass(frozen=True)
class Problem:
    """One problem of a study folder: where (file, 1-based line or None, field) and what."""

    file: str
    line: int | None
    field: str
    message: str

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}" if self.line else self.file
        return f"{where}: {self.field}: {self.message}" if self.field else f"{where}: {self.message}"


class Problems(list):
    """The problems found so far (a list of :class:`Problem`); checks add to it with :meth:`add`."""

    def add(self, file: str, line: int | None, fld: str, message: str) -> None:
        self.append(Problem(file, line, fld, message))
