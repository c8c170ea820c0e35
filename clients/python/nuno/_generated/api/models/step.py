from ...types import Unset
from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.error_body import ErrorBody
from ...models.step_request import StepRequest
from ...models.step_response import StepResponse
from ...types import File, FileTypes
from io import BytesIO
from typing import cast



def _get_kwargs(
    id: str,
    *,
    body:    StepRequest  |     File  | Unset = UNSET,

) -> dict[str, Any]:
    headers: dict[str, Any] = {}


    

    

    _kwargs: dict[str, Any] = {
        "method": "post",
        "url": "/v1/models/{id}/step".format(id=quote(str(id), safe=""),),
    }

    if isinstance(body, StepRequest):
        _kwargs["json"] = body.to_dict()

        headers["Content-Type"] = "application/json"
    if isinstance(body, File):
        _kwargs["content"] = body.payload
        headers["Content-Type"] = "application/octet-stream"

    _kwargs["headers"] = headers
    return _kwargs



def _parse_response(*, client: AuthenticatedClient | Client, response: httpx.Response) -> ErrorBody | StepResponse | None:
    if response.status_code == 200:
        response_200 = StepResponse.from_dict(response.json())



        return response_200

    if response.status_code == 400:
        response_400 = ErrorBody.from_dict(response.json())



        return response_400

    if response.status_code == 401:
        response_401 = ErrorBody.from_dict(response.json())



        return response_401

    if response.status_code == 404:
        response_404 = ErrorBody.from_dict(response.json())



        return response_404

    if response.status_code == 413:
        response_413 = ErrorBody.from_dict(response.json())



        return response_413

    if response.status_code == 415:
        response_415 = ErrorBody.from_dict(response.json())



        return response_415

    if response.status_code == 422:
        response_422 = ErrorBody.from_dict(response.json())



        return response_422

    if response.status_code == 500:
        response_500 = ErrorBody.from_dict(response.json())



        return response_500

    if response.status_code == 503:
        response_503 = ErrorBody.from_dict(response.json())



        return response_503

    if client.raise_on_unexpected_status:
        raise errors.UnexpectedStatus(response.status_code, response.content)
    else:
        return None


def _build_response(*, client: AuthenticatedClient | Client, response: httpx.Response) -> Response[ErrorBody | StepResponse]:
    return Response(
        status_code=HTTPStatus(response.status_code),
        content=response.content,
        headers=response.headers,
        parsed=_parse_response(client=client, response=response),
    )


def sync_detailed(
    id: str,
    *,
    client: AuthenticatedClient | Client,
    body:    StepRequest  |     File  | Unset = UNSET,

) -> Response[ErrorBody | StepResponse]:
    """ Samples one EM step. Binary bodies: a safetensors file with `states`
    `[batch, obs_dim]` and `actions` `[batch, act_dim]` (f32), the options as
    string metadata (`particles`, `seed`, `penalty`, `noise_scale`, `clip`); the answer
    is a safetensors file (`noise_scale` used and `clipped_rows` in its metadata) with `mean`, `sigma`,
    `h_eta` `[batch, obs_dim]`,
    `eta` `[batch]`, `next_states` `[batch, particles, obs_dim]`, `rewards`,
    `penalized_rewards`, `terminals` (0/1) `[batch, particles]`.

    Args:
        id (str):
        body (StepRequest): A batch of observations and actions to step.
        body (File): A safetensors file as a request or response body (f32 tensors, options as
            string metadata in its header).

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[ErrorBody | StepResponse]
     """


    kwargs = _get_kwargs(
        id=id,
body=body,

    )

    response = client.get_httpx_client().request(
        **kwargs,
    )

    return _build_response(client=client, response=response)

def sync(
    id: str,
    *,
    client: AuthenticatedClient | Client,
    body:    StepRequest  |     File  | Unset = UNSET,

) -> ErrorBody | StepResponse | None:
    """ Samples one EM step. Binary bodies: a safetensors file with `states`
    `[batch, obs_dim]` and `actions` `[batch, act_dim]` (f32), the options as
    string metadata (`particles`, `seed`, `penalty`, `noise_scale`, `clip`); the answer
    is a safetensors file (`noise_scale` used and `clipped_rows` in its metadata) with `mean`, `sigma`,
    `h_eta` `[batch, obs_dim]`,
    `eta` `[batch]`, `next_states` `[batch, particles, obs_dim]`, `rewards`,
    `penalized_rewards`, `terminals` (0/1) `[batch, particles]`.

    Args:
        id (str):
        body (StepRequest): A batch of observations and actions to step.
        body (File): A safetensors file as a request or response body (f32 tensors, options as
            string metadata in its header).

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        ErrorBody | StepResponse
     """


    return sync_detailed(
        id=id,
client=client,
body=body,

    ).parsed

async def asyncio_detailed(
    id: str,
    *,
    client: AuthenticatedClient | Client,
    body:    StepRequest  |     File  | Unset = UNSET,

) -> Response[ErrorBody | StepResponse]:
    """ Samples one EM step. Binary bodies: a safetensors file with `states`
    `[batch, obs_dim]` and `actions` `[batch, act_dim]` (f32), the options as
    string metadata (`particles`, `seed`, `penalty`, `noise_scale`, `clip`); the answer
    is a safetensors file (`noise_scale` used and `clipped_rows` in its metadata) with `mean`, `sigma`,
    `h_eta` `[batch, obs_dim]`,
    `eta` `[batch]`, `next_states` `[batch, particles, obs_dim]`, `rewards`,
    `penalized_rewards`, `terminals` (0/1) `[batch, particles]`.

    Args:
        id (str):
        body (StepRequest): A batch of observations and actions to step.
        body (File): A safetensors file as a request or response body (f32 tensors, options as
            string metadata in its header).

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[ErrorBody | StepResponse]
     """


    kwargs = _get_kwargs(
        id=id,
body=body,

    )

    response = await client.get_async_httpx_client().request(
        **kwargs
    )

    return _build_response(client=client, response=response)

async def asyncio(
    id: str,
    *,
    client: AuthenticatedClient | Client,
    body:    StepRequest  |     File  | Unset = UNSET,

) -> ErrorBody | StepResponse | None:
    """ Samples one EM step. Binary bodies: a safetensors file with `states`
    `[batch, obs_dim]` and `actions` `[batch, act_dim]` (f32), the options as
    string metadata (`particles`, `seed`, `penalty`, `noise_scale`, `clip`); the answer
    is a safetensors file (`noise_scale` used and `clipped_rows` in its metadata) with `mean`, `sigma`,
    `h_eta` `[batch, obs_dim]`,
    `eta` `[batch]`, `next_states` `[batch, particles, obs_dim]`, `rewards`,
    `penalized_rewards`, `terminals` (0/1) `[batch, particles]`.

    Args:
        id (str):
        body (StepRequest): A batch of observations and actions to step.
        body (File): A safetensors file as a request or response body (f32 tensors, options as
            string metadata in its header).

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        ErrorBody | StepResponse
     """


    return (await asyncio_detailed(
        id=id,
client=client,
body=body,

    )).parsed
