from ...types import Unset
from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.infer_request import InferRequest
from ...models.infer_response import InferResponse
from ...models.v2_error_body import V2ErrorBody
from ...types import File, FileTypes
from io import BytesIO
from typing import cast



def _get_kwargs(
    id: str,
    *,
    body:    InferRequest  |     File  | Unset = UNSET,

) -> dict[str, Any]:
    headers: dict[str, Any] = {}


    

    

    _kwargs: dict[str, Any] = {
        "method": "post",
        "url": "/v2/models/{id}/infer".format(id=quote(str(id), safe=""),),
    }

    if isinstance(body, InferRequest):
        _kwargs["json"] = body.to_dict()

        headers["Content-Type"] = "application/json"
    if isinstance(body, File):
        _kwargs["content"] = body.payload
        headers["Content-Type"] = "application/octet-stream"

    _kwargs["headers"] = headers
    return _kwargs



def _parse_response(*, client: AuthenticatedClient | Client, response: httpx.Response) -> InferResponse | V2ErrorBody | None:
    if response.status_code == 200:
        response_200 = InferResponse.from_dict(response.json())



        return response_200

    if response.status_code == 400:
        response_400 = V2ErrorBody.from_dict(response.json())



        return response_400

    if response.status_code == 401:
        response_401 = V2ErrorBody.from_dict(response.json())



        return response_401

    if response.status_code == 404:
        response_404 = V2ErrorBody.from_dict(response.json())



        return response_404

    if response.status_code == 413:
        response_413 = V2ErrorBody.from_dict(response.json())



        return response_413

    if response.status_code == 415:
        response_415 = V2ErrorBody.from_dict(response.json())



        return response_415

    if response.status_code == 422:
        response_422 = V2ErrorBody.from_dict(response.json())



        return response_422

    if response.status_code == 500:
        response_500 = V2ErrorBody.from_dict(response.json())



        return response_500

    if response.status_code == 503:
        response_503 = V2ErrorBody.from_dict(response.json())



        return response_503

    if client.raise_on_unexpected_status:
        raise errors.UnexpectedStatus(response.status_code, response.content)
    else:
        return None


def _build_response(*, client: AuthenticatedClient | Client, response: httpx.Response) -> Response[InferResponse | V2ErrorBody]:
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
    body:    InferRequest  |     File  | Unset = UNSET,

) -> Response[InferResponse | V2ErrorBody]:
    """ One EM step per row, in the v2 inference format. JSON, or the binary tensor
    extension (`application/octet-stream` with `Inference-Header-Content-Length`)
    both ways: inputs with `parameters.binary_data_size`, outputs in binary when
    asked (`parameters.binary_data_output`, or `binary_data` per output).

    Args:
        id (str):
        body (InferRequest):
        body (File): A safetensors file as a request or response body (f32 tensors, options as
            string metadata in its header).

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[InferResponse | V2ErrorBody]
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
    body:    InferRequest  |     File  | Unset = UNSET,

) -> InferResponse | V2ErrorBody | None:
    """ One EM step per row, in the v2 inference format. JSON, or the binary tensor
    extension (`application/octet-stream` with `Inference-Header-Content-Length`)
    both ways: inputs with `parameters.binary_data_size`, outputs in binary when
    asked (`parameters.binary_data_output`, or `binary_data` per output).

    Args:
        id (str):
        body (InferRequest):
        body (File): A safetensors file as a request or response body (f32 tensors, options as
            string metadata in its header).

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        InferResponse | V2ErrorBody
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
    body:    InferRequest  |     File  | Unset = UNSET,

) -> Response[InferResponse | V2ErrorBody]:
    """ One EM step per row, in the v2 inference format. JSON, or the binary tensor
    extension (`application/octet-stream` with `Inference-Header-Content-Length`)
    both ways: inputs with `parameters.binary_data_size`, outputs in binary when
    asked (`parameters.binary_data_output`, or `binary_data` per output).

    Args:
        id (str):
        body (InferRequest):
        body (File): A safetensors file as a request or response body (f32 tensors, options as
            string metadata in its header).

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[InferResponse | V2ErrorBody]
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
    body:    InferRequest  |     File  | Unset = UNSET,

) -> InferResponse | V2ErrorBody | None:
    """ One EM step per row, in the v2 inference format. JSON, or the binary tensor
    extension (`application/octet-stream` with `Inference-Header-Content-Length`)
    both ways: inputs with `parameters.binary_data_size`, outputs in binary when
    asked (`parameters.binary_data_output`, or `binary_data` per output).

    Args:
        id (str):
        body (InferRequest):
        body (File): A safetensors file as a request or response body (f32 tensors, options as
            string metadata in its header).

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        InferResponse | V2ErrorBody
     """


    return (await asyncio_detailed(
        id=id,
client=client,
body=body,

    )).parsed
