""" Contains all the data models used in inputs/outputs """

from .act_request import ActRequest
from .act_response import ActResponse
from .action_mode import ActionMode
from .candidate_score import CandidateScore
from .cost_request import CostRequest
from .cost_term_request import CostTermRequest
from .error_body import ErrorBody
from .error_detail import ErrorDetail
from .evaluate_request import EvaluateRequest
from .evaluate_response import EvaluateResponse
from .evaluation_report import EvaluationReport
from .health import Health
from .infer_input import InferInput
from .infer_input_parameters_type_0 import InferInputParametersType0
from .infer_request import InferRequest
from .infer_request_parameters import InferRequestParameters
from .infer_response import InferResponse
from .infer_response_outputs_item import InferResponseOutputsItem
from .infer_response_outputs_item_parameters_type_0 import InferResponseOutputsItemParametersType0
from .infer_response_parameters import InferResponseParameters
from .infer_tensor import InferTensor
from .infer_tensor_parameters_type_0 import InferTensorParametersType0
from .live_response_200 import LiveResponse200
from .load_failure import LoadFailure
from .model_detail import ModelDetail
from .model_detail_dataset import ModelDetailDataset
from .model_detail_hyperparameters import ModelDetailHyperparameters
from .model_detail_policy import ModelDetailPolicy
from .model_detail_state_split import ModelDetailStateSplit
from .model_detail_thresholds import ModelDetailThresholds
from .model_detail_training import ModelDetailTraining
from .model_kind import ModelKind
from .model_list import ModelList
from .model_ready_response_200 import ModelReadyResponse200
from .model_summary import ModelSummary
from .plan_request import PlanRequest
from .plan_response import PlanResponse
from .planner import Planner
from .readiness import Readiness
from .ready_response_200 import ReadyResponse200
from .ready_response_503 import ReadyResponse503
from .reload_report import ReloadReport
from .requested_output import RequestedOutput
from .requested_output_name import RequestedOutputName
from .requested_output_parameters_type_0 import RequestedOutputParametersType0
from .rollout_request import RolloutRequest
from .rollout_response import RolloutResponse
from .score_response import ScoreResponse
from .server_metadata_response_200 import ServerMetadataResponse200
from .step_request import StepRequest
from .step_response import StepResponse
from .system_description import SystemDescription
from .system_description_bounds import SystemDescriptionBounds
from .trajectory import Trajectory
from .v2_error_body import V2ErrorBody
from .v2_model_metadata import V2ModelMetadata
from .v2_tensor_metadata import V2TensorMetadata
from .validate_request import ValidateRequest
from .validate_response import ValidateResponse

__all__ = (
    "ActionMode",
    "ActRequest",
    "ActResponse",
    "CandidateScore",
    "CostRequest",
    "CostTermRequest",
    "ErrorBody",
    "ErrorDetail",
    "EvaluateRequest",
    "EvaluateResponse",
    "EvaluationReport",
    "Health",
    "InferInput",
    "InferInputParametersType0",
    "InferRequest",
    "InferRequestParameters",
    "InferResponse",
    "InferResponseOutputsItem",
    "InferResponseOutputsItemParametersType0",
    "InferResponseParameters",
    "InferTensor",
    "InferTensorParametersType0",
    "LiveResponse200",
    "LoadFailure",
    "ModelDetail",
    "ModelDetailDataset",
    "ModelDetailHyperparameters",
    "ModelDetailPolicy",
    "ModelDetailStateSplit",
    "ModelDetailThresholds",
    "ModelDetailTraining",
    "ModelKind",
    "ModelList",
    "ModelReadyResponse200",
    "ModelSummary",
    "Planner",
    "PlanRequest",
    "PlanResponse",
    "Readiness",
    "ReadyResponse200",
    "ReadyResponse503",
    "ReloadReport",
    "RequestedOutput",
    "RequestedOutputName",
    "RequestedOutputParametersType0",
    "RolloutRequest",
    "RolloutResponse",
    "ScoreResponse",
    "ServerMetadataResponse200",
    "StepRequest",
    "StepResponse",
    "SystemDescription",
    "SystemDescriptionBounds",
    "Trajectory",
    "V2ErrorBody",
    "V2ModelMetadata",
    "V2TensorMetadata",
    "ValidateRequest",
    "ValidateResponse",
)
