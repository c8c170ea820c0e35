-- wrk script: POST the file args[1] with content type args[2] on every request,
-- asking for the answer as args[3] when given (e.g. application/octet-stream).
function init(args)
  local f = assert(io.open(args[1], "rb"))
  local body = f:read("*a")
  f:close()
  local headers = { ["Content-Type"] = args[2] }
  if args[3] then
    headers["Accept"] = args[3]
  end
  req = wrk.format("POST", nil, headers, body)
end

function request()
  return req
end
