-- wrk script: POST the file args[1] with content type args[2] on every request.
function init(args)
  local f = assert(io.open(args[1], "rb"))
  local body = f:read("*a")
  f:close()
  req = wrk.format("POST", nil, { ["Content-Type"] = args[2] }, body)
end

function request()
  return req
end
