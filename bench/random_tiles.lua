-- wrk script for bench/serve_bench.sh: requests random entries of a list file.
--   wrk ... -s bench/random_tiles.lua URL -- LIST [MODE]
-- LIST: one entry per line. MODE tiles (default): "PATH"; inm: "PATH ETAG" sent as If-None-Match
-- (expects 304); range: "PATH START END" sent as Range: bytes=START-END (expects 206).
-- Any other status is counted and reported by done() (wrk also prints non-2xx/3xx counts).
local entries = {}
local mode = "tiles"
local unexpected = 0
local want = { tiles = 200, inm = 304, range = 206 }

function init(args)
  mode = args[2] or "tiles"
  for line in io.lines(args[1]) do
    local p, a, b = line:match("^(%S+)%s*(%S*)%s*(%S*)")
    if p then entries[#entries + 1] = { p, a, b } end
  end
  if #entries == 0 then error("empty list " .. args[1]) end
  math.randomseed(math.floor(os.clock() * 1e6) + #tostring({}))
end

function request()
  local e = entries[math.random(#entries)]
  if mode == "inm" then
    return wrk.format("GET", e[1], { ["If-None-Match"] = e[2] })
  elseif mode == "range" then
    return wrk.format("GET", e[1], { ["Range"] = "bytes=" .. e[2] .. "-" .. e[3] })
  end
  return wrk.format("GET", e[1])
end

function response(status, headers, body)
  if status ~= want[mode] then unexpected = unexpected + 1 end
end
