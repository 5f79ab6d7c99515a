-- wrk script: GET every segment in turn. Arguments: PREFIX COUNT (e.g. /v1/segments/ 2018).
local prefix, count, i = "/v1/segments/", 1, 0

function init(args)
  prefix = args[1] or prefix
  count = tonumber(args[2] or "1")
  -- Each wrk thread starts at a different place in the list.
  i = math.random(0, count - 1)
end

function request()
  i = (i + 1) % count
  return wrk.format("GET", prefix .. i)
end
