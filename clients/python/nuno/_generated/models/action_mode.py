from enum import StrEnum

class ActionMode(StrEnum):
    DETERMINISTIC = "deterministic"
    SAMPLED = "sampled"

    def __str__(self) -> str:
        return str(self.value)
