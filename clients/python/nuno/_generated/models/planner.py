from enum import StrEnum

class Planner(StrEnum):
    CEM = "cem"
    ICEM = "icem"
    MPPI = "mppi"

    def __str__(self) -> str:
        return str(self.value)
