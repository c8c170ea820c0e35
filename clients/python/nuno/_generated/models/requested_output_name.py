from enum import StrEnum

class RequestedOutputName(StrEnum):
    ETA = "eta"
    H_ETA = "h_eta"
    MEAN = "mean"
    NEXT_STATES = "next_states"
    PENALIZED_REWARDS = "penalized_rewards"
    REWARDS = "rewards"
    SIGMA = "sigma"
    TERMINALS = "terminals"

    def __str__(self) -> str:
        return str(self.value)
