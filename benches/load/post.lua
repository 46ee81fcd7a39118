-- wrk script: POST the JSON body of the file BODY to the path URL_PATH.
--   BODY=/tmp/jpda-500.json URL_PATH=/v1/jpda/update wrk -t1 -c1 -d10s -s benches/load/post.lua http://127.0.0.1:8080
-- (`cargo run --release --example request_path -- --dump /tmp/jpda-500.json` writes the JPDA body.)
local f = assert(io.open(os.getenv("BODY"), "rb"))
wrk.method = "POST"
wrk.path = os.getenv("URL_PATH")
wrk.headers["Content-Type"] = "application/json"
wrk.body = f:read("*a")
f:close()

done = function(summary, latency, requests)
  io.write(string.format("non-2xx responses: %d\n", summary.errors.status))
end
