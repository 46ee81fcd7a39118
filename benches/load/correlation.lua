-- wrk script: POST a correlation request read from a file (default
-- /tmp/corr-120.json, made by `cargo run --release --example correlation_payload`).
--   BODY=/tmp/corr-120.json wrk -t2 -c4 -d10s --latency -s benches/load/correlation.lua http://127.0.0.1:8080
local path = os.getenv("BODY") or "/tmp/corr-120.json"
local f = assert(io.open(path, "rb"))
wrk.method = "POST"
wrk.path = "/v1/correlation/tracks"
wrk.headers["Content-Type"] = "application/json"
wrk.body = f:read("*a")
f:close()

done = function(summary, latency, requests)
  io.write(string.format("non-2xx responses: %d\n", summary.errors.status))
end
