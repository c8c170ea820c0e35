from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.error_body import ErrorBody
from ...models.plan_request import PlanRequest
from ...models.plan_response import PlanResponse
from typing import cast



def _get_kwargs(
    id: str,
    *,
    body: PlanRequest,

) -> dict[str, Any]:
    headers: dict[str, Any] = {}


    

    

    _kwargs: dict[str, Any] = {
        "method": "post",
        "url": "/v1/models/{id}/plan".format(id=quote(str(id), safe=""),),
    }

    _kwargs["json"] = body.to_dict()

    headers["Content-Type"] = "application/json"

    _kwargs["headers"] = headers
    return _kwargs



def _parse_response(*, client: AuthenticatedClient | Client, response: httpx.Response) -> ErrorBody | PlanResponse | None:
    if response.status_code == 200:
        response_200 = PlanResponse.from_dict(response.json())



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


def _build_response(*, client: AuthenticatedClient | Client, response: httpx.Response) -> Response[ErrorBody | PlanResponse]:
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
    body: PlanRequest,

) -> Response[ErrorBody | PlanResponse]:
    """ Plans `horizon` actions from `state` with MPPI, CEM or iCEM over the model's
    η-penalised (or CVaR) returns, mbrl-lib's planners (docs/paper-map.md).
    With `open_session` the plan is kept under a new session id; with
    `session` the search starts from that session's last plan shifted one
    step (iCEM also from its last elites), and the new plan replaces it. An unknown or expired session
    is a 404.

    Args:
        id (str):
        body (PlanRequest):

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[ErrorBody | PlanResponse]
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
    body: PlanRequest,

) -> ErrorBody | PlanResponse | None:
    """ Plans `horizon` actions from `state` with MPPI, CEM or iCEM over the model's
    η-penalised (or CVaR) returns, mbrl-lib's planners (docs/paper-map.md).
    With `open_session` the plan is kept under a new session id; with
    `session` the search starts from that session's last plan shifted one
    step (iCEM also from its last elites), and the new plan replaces it. An unknown or expired session
    is a 404.

    Args:
        id (str):
        body (PlanRequest):

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        ErrorBody | PlanResponse
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
    body: PlanRequest,

) -> Response[ErrorBody | PlanResponse]:
    """ Plans `horizon` actions from `state` with MPPI, CEM or iCEM over the model's
    η-penalised (or CVaR) returns, mbrl-lib's planners (docs/paper-map.md).
    With `open_session` the plan is kept under a new session id; with
    `session` the search starts from that session's last plan shifted one
    step (iCEM also from its last elites), and the new plan replaces it. An unknown or expired session
    is a 404.

    Args:
        id (str):
        body (PlanRequest):

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[ErrorBody | PlanResponse]
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
    body: PlanRequest,

) -> ErrorBody | PlanResponse | None:
    """ Plans `horizon` actions from `state` with MPPI, CEM or iCEM over the model's
    η-penalised (or CVaR) returns, mbrl-lib's planners (docs/paper-map.md).
    With `open_session` the plan is kept under a new session id; with
    `session` the search starts from that session's last plan shifted one
    step (iCEM also from its last elites), and the new plan replaces it. An unknown or expired session
    is a 404.

    Args:
        id (str):
        body (PlanRequest):

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        ErrorBody | PlanResponse
     """


    return (await asyncio_detailed(
        id=id,
client=client,
body=body,

    )).parsed
