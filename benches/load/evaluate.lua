-- wrk script: POST the L/R rule evaluation (seed 000 eq. 23).
--   wrk -t2 -c16 -d10s --latency -s benches/load/evaluate.lua http://127.0.0.1:8080
wrk.method = "POST"
wrk.path = "/v1/correlation/rules/evaluate"
wrk.headers["Content-Type"] = "application/json"
wrk.body = '{"alpha": 0.05, "rules": [{"l": 3, "r": 4}, {"l": 6, "r": 8}]}'

done = function(summary, latency, requests)
  local non2xx = summary.errors.status
  io.write(string.format("non-2xx responses: %d\n", non2xx))
end
