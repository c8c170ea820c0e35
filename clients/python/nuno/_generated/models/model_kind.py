from enum import StrEnum

class ModelKind(StrEnum):
    GAUSSIAN_ENSEMBLE = "gaussian-ensemble"
    NEURAL_SDE = "neural-sde"

    def __str__(self) -> str:
        return str(self.value)
