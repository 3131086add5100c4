#!/usr/bin/env bash
# CI smoke test against a live server, with nothing but curl (python3 only reads the JSON).
#   BASE_URL=http://127.0.0.1:8000 SMOKE_CLIENT_KEY=... SMOKE_SUPERVISOR_KEY=... scripts/smoke.sh
set -euo pipefail
BASE_URL="${BASE_URL:-http://127.0.0.1:8000}"
CLIENT=(); SUPERVISOR=()
[ -n "${SMOKE_CLIENT_KEY:-}" ] && CLIENT=(-H "Authorization: Bearer ${SMOKE_CLIENT_KEY}")
[ -n "${SMOKE_SUPERVISOR_KEY:-}" ] && SUPERVISOR=(-H "Authorization: Bearer ${SMOKE_SUPERVISOR_KEY}")
TMP="$(mktemp -d)"; trap 'rm -rf "$TMP"' EXIT
fail() { echo "smoke: FAIL: $*" >&2; exit 1; }

# call METHOD PATH [BODY] [auth...] -> body in $TMP/out, status echoed
call() {
  local method="$1" path="$2" body="${3:-}"; shift 3 || shift $#
  local args=(-sS -o "$TMP/out" -w '%{http_code}' -X "$method" "$@")
  [ -n "$body" ] && args+=(-H 'content-type: application/json' --data "$body")
  curl "${args[@]}" "$BASE_URL$path"
}
# check PYTHON-EXPRESSION-over-`d` MESSAGE
check() { python3 -c "import json,sys; d=json.load(open('$TMP/out')); sys.exit(0 if ($1) else 1)" \
          || fail "$2: $(head -c 400 "$TMP/out")"; }

[ "$(call GET /health '')" = 200 ] || fail "/health"
check 'd["status"] == "ok"' "health status"

[ "$(call GET /solvers '' "${CLIENT[@]}")" = 200 ] || fail "/solvers"
solvers=$(python3 -c "import json; print(' '.join(s['name'] for s in json.load(open('$TMP/out'))))")
echo "smoke: solvers: $solvers"
for solver in greedy dp optimal q_learning dqn ltaa brute_force; do
  case " $solvers " in *" $solver "*) ;; *) fail "solver $solver not listed";; esac
done

for solver in $solvers; do
  case "$solver" in
    brute_force) body='{"solver":"brute_force","tasks":[{"id":1,"features":["heavy"]},{"id":2,"features":["careful"]},{"id":3,"features":["dexterous"]}],"robots":[{"name":"a","success":{"heavy":0.9,"careful":0.2,"dexterous":0.5}},{"name":"b","success":{"heavy":0.3,"careful":0.8,"dexterous":0.6}}]}' ;;
    dqn) body='{"solver":"dqn","scenario":"baseline","options":{"timesteps":2000}}' ;;
    q_learning) body='{"solver":"q_learning","scenario":"baseline","options":{"episodes":2000}}' ;;
    *) body="{\"solver\":\"$solver\",\"scenario\":\"baseline\",\"mode\":\"balanced\"}" ;;
  esac
  code=$(call POST /allocate "$body" "${CLIENT[@]}")
  [ "$code" = 200 ] || fail "/allocate $solver -> $code $(head -c 300 "$TMP/out")"
  check 'len(d["assignments"]) in (3, 36) and 0 < d["metrics"]["expected_success"] <= 1' \
        "/allocate $solver body"
  echo "smoke: /allocate $solver ok ($(python3 -c "import json; d=json.load(open('$TMP/out')); print(round(d['metrics']['expected_success'], 4))"))"
done

code=$(call POST /allocate '{"solver":"dp","scenario":"baseline","max_deviation":-1}' "${CLIENT[@]}")
[ "$code" = 422 ] || fail "bad input should be 422, got $code"
check 'd["detail"][0]["loc"][-1] == "max_deviation"' "422 names the field"

# Time (docs/api.md#plans-in-time): a timed instance, planned by the exact `schedule` solver; six
# tasks it proves.
timed='{"solver":"schedule","mode":"success_focused","start":"2026-03-02T07:00:00+01:00","travel":{"A":{"B":3,"C":5},"B":{"C":4}},"options":{"time_limit_s":10},
 "robots":[{"name":"a","success":{"heavy":0.9,"dexterous":0.4},"zone":"A","available":[0,200]},{"name":"b","success":{"heavy":0.5,"dexterous":0.85},"zone":"C","available":[10,200]}],
 "tasks":[{"id":"dig","features":["heavy"],"duration":{"a":20,"b":30},"zone":"A"},{"id":"frame","features":["heavy","dexterous"],"duration":15,"zone":"B","after":["dig"]},
  {"id":"wire","features":["dexterous"],"duration":{"a":25,"b":12},"zone":"B","after":["frame"]},{"id":"paint","features":["dexterous"],"duration":10,"zone":"C","release":20},
  {"id":"lift","features":["heavy"],"duration":{"a":18,"b":22},"zone":"C"},{"id":"check","features":["dexterous"],"duration":8,"zone":"A","after":["wire","paint"],"deadline":150}]}'
code=$(call POST /allocate "$timed" "${CLIENT[@]}")
[ "$code" = 200 ] || fail "timed /allocate schedule -> $code $(head -c 300 "$TMP/out")"
check 'd["status"] == "optimal" and d["schedule"]["makespan"] == 72 and d["bound"] == 72 and d["schedule_violations"] == []' "timed schedule: optimal makespan 72"
check 'len(d["schedule"]["tasks"]) == 6 and d["schedule"]["tasks"][0]["start_at"].startswith("2026-03-02T07:")' "timed schedule: one slot per task, wall-clock times"
cycle=$(printf '%s' "$timed" | sed 's/"after":\["dig"\]/"after":["check"]/')  # dig waits for check
code=$(call POST /allocate "$cycle" "${CLIENT[@]}")
[ "$code" = 422 ] || fail "a precedence cycle should be 422, got $code"
check 'd["detail"][0]["loc"][:2] == ["body", "tasks"] and "cycle" in d["detail"][0]["msg"]' "422 names the cycle's task"
echo "smoke: timed /allocate ok (schedule optimal, makespan 72; a cycle is 422)"
# A typed link (docs/schedules.md#links): wiring starts 5 minutes after framing starts.
typed=$(printf '%s' "$timed" | sed 's/"after":\["frame"\]/"after":[{"task":"frame","type":"SS","lag":5}]/')
code=$(call POST /allocate "$typed" "${CLIENT[@]}")
[ "$code" = 200 ] || fail "typed-link /allocate schedule -> $code $(head -c 300 "$TMP/out")"
check 'd["status"] == "optimal" and d["schedule_violations"] == [] and d["schedule"]["tasks"][2]["start"] >= d["schedule"]["tasks"][1]["start"] + 5' "typed link: wire starts 5 min after frame starts"
echo "smoke: typed-link /allocate ok"

# Teams (docs/allocation.md#teams): a beam two heavy robots lift, a panel a heavy and a careful
# robot fix; the crane may do heavy work only. `optimal` answers whole teams.
team='{"solver":"optimal","mode":"success_focused",
 "tasks":[{"id":"beam","team":{"heavy":2}},{"id":"panel","team":{"heavy":1,"careful":1}},{"id":"sweep","features":["careful"]}],
 "robots":[{"name":"crane","success":{"heavy":0.9,"careful":0.2},"skills":["heavy"]},{"name":"arm","success":{"heavy":0.3,"careful":0.95}},{"name":"lifter","success":{"heavy":0.8,"careful":0.4}}]}'
code=$(call POST /allocate "$team" "${CLIENT[@]}")
[ "$code" = 200 ] || fail "team /allocate optimal -> $code $(head -c 300 "$TMP/out")"
check 'd["assignments"][0]["team"] == [{"robot": "crane", "feature": "heavy"}, {"robot": "lifter", "feature": "heavy"}] and d["assignments"][0]["robot"] == "crane"' "team answer: the beam's two members"
check '[m["feature"] for m in d["assignments"][1]["team"]] == ["heavy", "careful"] and "team" not in d["assignments"][2] and sum(d["metrics"]["workload"].values()) == 5' "team answer: one member per unit, loads count units"
echo "smoke: team /allocate ok (optimal forms the teams)"

# Teams in time (docs/schedules.md#teams-in-time): the beam's two members travel to it and
# work it together; `schedule` proves the plan and shows the panel in both members' lanes.
tteam='{"solver":"schedule","mode":"success_focused","start":"2026-12-07T07:00:00+01:00","travel":{"north":{"south":6}},
 "tasks":[{"id":"beam","team":{"heavy":2},"duration":30,"zone":"north"},{"id":"panel","team":{"heavy":1,"careful":1},"duration":20,"zone":"south","after":["beam"]},
  {"id":"sweep","features":["careful"],"duration":15,"zone":"south"},{"id":"carry","features":["heavy"],"duration":10,"zone":"north"}],
 "robots":[{"name":"crane","success":{"heavy":0.9,"careful":0.2},"skills":["heavy"],"zone":"north"},{"name":"arm","success":{"heavy":0.3,"careful":0.95},"zone":"south"},{"name":"lifter","success":{"heavy":0.8,"careful":0.4},"zone":"north"}]}'
code=$(call POST /allocate "$tteam" "${CLIENT[@]}")
[ "$code" = 200 ] || fail "timed team /allocate schedule -> $code $(head -c 300 "$TMP/out")"
check 'd["status"] == "optimal" and d["schedule"]["makespan"] == 66 and d["schedule_violations"] == []' "timed team schedule: optimal makespan 66"
check 'all(any(i.get("task_id") == "panel" for i in d["schedule"]["robots"][m["robot"]]["lane"]) for m in d["assignments"][1]["team"])' "timed team schedule: the panel in each member's lane"
echo "smoke: timed team /allocate ok (schedule optimal, makespan 66)"

# The README tour's step 11 (docs/fleet.md): three simulated VDA 5050 robots take a timed plan's
# orders, a planned minute in 0.05 s, and report all 36 tasks themselves within 30 s. .ci/run
# serves with a broker (SMOKE_FLEET=1, SMOKE_MQTT_URL, SMOKE_MQTT_INTERFACE). The first run here:
# a plan made earlier on the default site would go to the robots first.
if [ "${SMOKE_FLEET:-0}" = 1 ]; then
  "${LTAA_BIN:-.venv/bin/}ltaa" fleet simulate --url "${SMOKE_MQTT_URL:-mqtt://127.0.0.1:1883}" \
    --interface "${SMOKE_MQTT_INTERFACE:-uagv}" --names heavy,medium,light --speed 1200 \
    < /dev/null > "$TMP/robots.log" 2>&1 &
  SIM_PID=$!
  trap 'kill "$SIM_PID" 2>/dev/null || true; rm -rf "$TMP"' EXIT
  for _ in $(seq 1 100); do
    call GET /fleet/robots '' "${CLIENT[@]}" > /dev/null
    python3 -c "import json,sys; d=json.load(open('$TMP/out')); sys.exit(0 if sum(r['connection'] == 'ONLINE' for r in d['robots']) == 3 else 1)" && break
    sleep 0.2
  done
  check 'sum(r["connection"] == "ONLINE" for r in d["robots"]) == 3' "three simulated robots ONLINE"
  code=$(call POST /runs '{"scenario":"baseline_timed","reasoner":"rules"}' "${CLIENT[@]}")
  [ "$code" = 202 ] || fail "POST /runs for the robots -> $code $(head -c 300 "$TMP/out")"
  fleet_id=$(python3 -c "import json; print(json.load(open('$TMP/out'))['id'])")
  started=$SECONDS
  for _ in $(seq 1 150); do
    [ "$(call GET "/runs/$fleet_id" '' "${CLIENT[@]}")" = 200 ] || fail "GET /runs/$fleet_id"
    python3 -c "import json,sys; d=json.load(open('$TMP/out')); sys.exit(0 if d['status'] == 'completed' and all((a.get('execution') or {}).get('state') in ('done', 'failed') for a in d['assignments']) else 1)" && break
    [ $((SECONDS - started)) -lt 30 ] || break
    sleep 0.2
  done
  check 'd["status"] == "completed" and len(d["assignments"]) == 36 and all((a.get("execution") or {}).get("state") in ("done", "failed") for a in d["assignments"])' "every task reported by the robots within 30 s ($(tail -3 "$TMP/robots.log" | tr '\n' ' '))"
  kill "$SIM_PID"; wait "$SIM_PID" || fail "the simulator did not stop cleanly at SIGTERM"
  grep -q "heavy OFFLINE" "$TMP/robots.log" || fail "the robots did not say OFFLINE"
  echo "smoke: the robots did run $fleet_id in $((SECONDS - started)) s (README step 11)"
fi

code=$(call POST /runs '{"scenario":"baseline","mode":"balanced","reasoner":"rules"}' "${CLIENT[@]}")
[ "$code" = 202 ] || fail "POST /runs -> $code"
run_id=$(python3 -c "import json; print(json.load(open('$TMP/out'))['id'])")
echo "smoke: run $run_id created"
for _ in $(seq 1 300); do
  [ "$(call GET "/runs/$run_id" '' "${CLIENT[@]}")" = 200 ] || fail "GET /runs/$run_id"
  status=$(python3 -c "import json; print(json.load(open('$TMP/out'))['status'])")
  case "$status" in completed) break;; failed|cancelled) fail "run ended $status";; esac
  sleep 0.2
done
[ "$status" = completed ] || fail "run did not complete in time (status $status)"
check 'd["progress"]["allocated"] == 36 and sum(d["workload"].values()) == 36 and d["metrics"]' \
      "completed run"

[ "$(call GET "/runs/$run_id/trace?include=prompts" '' "${SUPERVISOR[@]}")" = 200 ] || fail "trace"
check '[x["task_index"] for x in d["decisions"]] == list(range(36))' "36 decision records"
check 'all(x["attempts"] and x["attempts"][0]["scores"] and x["reasoning"] for x in d["decisions"])' \
      "each decision has validated attempts and reasoning"
check 'd["decisions"][0]["attempts"][0]["user_prompt"]' "prompts included"
check '[e["kind"] for e in d["events"]][-1] == "completed"' "completed event"
[ "$(call GET "/runs/$run_id/trace/verify" '' "${SUPERVISOR[@]}")" = 200 ] || fail "trace/verify"; check 'd["ok"] is True and d["decisions"] == 36 and d["broken"] is None' "trace hash chains verify"
[ "$(call GET "/runs/$run_id/trace?format=jsonl" '' "${SUPERVISOR[@]}")" = 200 ] && python3 -c "import json; t=[json.loads(l)['type'] for l in open('$TMP/out')]; assert t[0] == 'run' and t[-1] == 'end' and t.count('decision') == 36" || fail "jsonl trace: $(head -c 300 "$TMP/out")"
[ "$(call POST "/runs/$run_id/resume" '' "${SUPERVISOR[@]}")" = 409 ] || fail "resume completed run should be 409"
# Living plans: execution reports (forward only) on the completed run, then a revision
# with the heavy robot unavailable and tasks 0-17 pinned; the parent stays completed.
[ "$(call GET "/runs/$run_id" '' "${CLIENT[@]}")" = 200 ] || fail "GET /runs/$run_id"
first_task=$(python3 -c "import json; print(json.dumps(json.load(open('$TMP/out'))['assignments'][0]['task_id']))")
[ "$(call POST "/runs/$run_id/execution" "{\"updates\":[{\"task_id\":$first_task,\"state\":\"done\"}]}" "${CLIENT[@]}")" = 200 ] || fail "execution report -> $(head -c 300 "$TMP/out")"
check "d['states'] == {str($first_task): 'done'}" "execution report stored"
[ "$(call POST "/runs/$run_id/execution" "{\"updates\":[{\"task_id\":$first_task,\"state\":\"started\"}]}" "${CLIENT[@]}")" = 409 ] || fail "a state going backwards should be 409"
code=$(call POST "/runs/$run_id/revisions" '{"changes":[{"type":"robot_unavailable","robot":"heavy"}],"pin":{"through_task_index":17},"reason":"smoke: heavy robot fault"}' "${CLIENT[@]}")
[ "$code" = 202 ] || fail "POST /runs/$run_id/revisions -> $code $(head -c 300 "$TMP/out")"
revision_id=$(python3 -c "import json; print(json.load(open('$TMP/out'))['id'])")
for _ in $(seq 1 300); do
  [ "$(call GET "/runs/$revision_id" '' "${CLIENT[@]}")" = 200 ] || fail "GET /runs/$revision_id"
  status=$(python3 -c "import json; print(json.load(open('$TMP/out'))['status'])")
  case "$status" in completed) break;; failed|cancelled) fail "revision ended $status";; esac
  sleep 0.2
done
[ "$status" = completed ] || fail "revision did not complete in time (status $status)"
check 'd["revision_of"] and sum(a["pinned"] for a in d["assignments"]) == 18 and all(a["robot"] != "heavy" for a in d["assignments"] if not a["pinned"])' "revision keeps the pins, avoids heavy"
[ "$(call GET "/runs/$run_id" '' "${CLIENT[@]}")" = 200 ] || fail "GET parent"
check "d['status'] == 'completed' and d['superseded_by'] == '$revision_id'" "completed parent stays completed"
[ "$(call GET "/runs/$revision_id/diff" '' "${CLIENT[@]}")" = 200 ] || fail "diff"
check 'd["fleet_changes"] == [{"robot": "heavy", "change": "unavailable"}]' "diff names the fleet change"
[ "$(call GET "/runs/$revision_id/trace/verify" '' "${SUPERVISOR[@]}")" = 200 ] || fail "revision verify"
check "d['ok'] is True and d['parent']['run_id'] == '$run_id' and d['parent']['ok']" "revision verifies with its parent link"
[ "$(call GET "/runs/$run_id/trace/verify" '' "${SUPERVISOR[@]}")" = 200 ] || fail "parent verify"
check 'd["ok"] is True' "completed parent still verifies after reports and a revision"
echo "smoke: living plans ok (execution reports, revision $revision_id, diff, verify)"
# Sites (docs/estimates.md#using-the-estimates): the report above taught the default site; a learned
# run records its numbers.
[ "$(call GET /sites '' "${CLIENT[@]}")" = 200 ] || fail "GET /sites"
check 'any(s["site"] == "default" and s["reports"] >= 1 for s in d)' "the default site counts the report"
[ "$(call GET /sites/default/estimates '' "${CLIENT[@]}")" = 200 ] || fail "GET /sites/default/estimates"
check 'd["reports"] >= 1 and all(f["interval"][0] <= f["posterior_mean"] <= f["interval"][1] for r in d["robots"] for f in r["features"])' "estimates with intervals"
[ "$(call GET /sites/no-such-site/estimates '' "${CLIENT[@]}")" = 404 ] || fail "an unknown site should be 404"
[ "$(call GET '/sites/default/estimates?as_of=2026-12-01T09:30:00' '' "${CLIENT[@]}")" = 422 ] || fail "as_of without an offset should be 422"
[ "$(call POST /runs '{"scenario":"baseline","rates":"guessed"}' "${CLIENT[@]}")" = 422 ] || fail "rates not configured|learned|sampled should be 422"
code=$(call POST /runs '{"scenario":"baseline","reasoner":"rules","rates":"learned"}' "${CLIENT[@]}")
[ "$code" = 202 ] || fail "POST /runs rates learned -> $code $(head -c 300 "$TMP/out")"
learned_id=$(python3 -c "import json; print(json.load(open('$TMP/out'))['id'])")
[ "$(call GET "/runs/$learned_id/trace" '' "${SUPERVISOR[@]}")" = 200 ] || fail "trace of the learned run"
check 'd["events"][0]["detail"]["learned"]["source"] == "learned" and d["events"][0]["detail"]["learned"]["reports"] >= 1' "the learned run's first event records its numbers"
echo "smoke: sites ok (estimates, 404, 422s, a learned run $learned_id)"
# The fleet (docs/fleet.md#the-robots): the robots the VDA 5050 bridge has heard from. .ci/run
# serves with a broker (SMOKE_FLEET=1): the bridge must be on and connected.
[ "$(call GET /fleet/robots '' "${CLIENT[@]}")" = 200 ] || fail "GET /fleet/robots"
check 'isinstance(d["robots"], list) and "interface" in d' "the fleet answers"
if [ "${SMOKE_FLEET:-0}" = 1 ]; then
  for _ in $(seq 1 50); do
    call GET /fleet/robots '' "${CLIENT[@]}" > /dev/null
    python3 -c "import json,sys; d=json.load(open('$TMP/out')); sys.exit(0 if d['enabled'] and d['connected'] else 1)" && break
    sleep 0.2
  done
  check 'd["enabled"] is True and d["connected"] is True' "the fleet bridge is connected to the broker"
fi
echo "smoke: fleet ok"
# A run in time (docs/schedules.md#runs-in-time): the timed scenario decided by LTAA, its schedule
# as JSON, CSV and iCalendar; an untimed run has no schedule (409). GET /scenarios says which one is
# timed.
[ "$(call GET /scenarios '' "${CLIENT[@]}")" = 200 ] || fail "GET /scenarios"
check 'any(s["name"] == "baseline_timed" and s["timed"] and all(t["duration"] for t in s["tasks"]) for s in d)' "GET /scenarios lists baseline_timed with its durations"
code=$(call POST /runs '{"scenario":"baseline_timed","reasoner":"rules"}' "${CLIENT[@]}")
[ "$code" = 202 ] || fail "POST /runs baseline_timed -> $code $(head -c 300 "$TMP/out")"
timed_id=$(python3 -c "import json; print(json.load(open('$TMP/out'))['id'])")
for _ in $(seq 1 300); do
  [ "$(call GET "/runs/$timed_id" '' "${CLIENT[@]}")" = 200 ] || fail "GET /runs/$timed_id"
  status=$(python3 -c "import json; print(json.load(open('$TMP/out'))['status'])")
  case "$status" in completed) break;; failed|cancelled) fail "timed run ended $status";; esac
  sleep 0.2
done
[ "$status" = completed ] || fail "timed run did not complete in time (status $status)"
[ "$(call GET "/runs/$timed_id/schedule" '' "${CLIENT[@]}")" = 200 ] || fail "GET /runs/$timed_id/schedule"
check 'len(d["tasks"]) == 36 and d["makespan"] > 0 and d["critical_path"] and all(t["start_at"] for t in d["tasks"])' "a timed run's schedule: 36 tasks with wall-clock times"
[ "$(call GET "/runs/$timed_id/schedule?format=csv" '' "${CLIENT[@]}")" = 200 ] || fail "schedule as CSV"
[ "$(python3 -c "import csv; print(len(list(csv.DictReader(open('$TMP/out')))))")" = 36 ] || fail "the CSV has one row per task"
[ "$(call GET "/runs/$timed_id/schedule?format=ics" '' "${CLIENT[@]}")" = 200 ] || fail "schedule as iCalendar"
[ "$(grep -c '^BEGIN:VEVENT' "$TMP/out")" = 36 ] || fail "the iCalendar has one VEVENT per task"
[ "$(call GET "/runs/$run_id/schedule" '' "${CLIENT[@]}")" = 409 ] || fail "an untimed run's schedule should be 409"
echo "smoke: plans in time ok (run $timed_id, schedule as JSON, CSV and iCalendar; untimed 409)"

# Schedule files (docs/exchange.md): a small MS Project XML file imports to a draft (a typed link
# kept, features from default_features), the timed run's plan exports as MSPDI, which imports back.
cat > "$TMP/plan.xml" <<'XML'
<?xml version="1.0" encoding="UTF-8"?>
<Project xmlns="http://schemas.microsoft.com/project">
  <Name>Smoke slab</Name><StartDate>2026-03-02T08:00:00</StartDate>
  <Tasks>
    <Task><UID>1</UID><Name>Formwork</Name><Duration>PT2H0M0S</Duration></Task>
    <Task><UID>2</UID><Name>Pour</Name><Duration>PT1H30M0S</Duration>
      <PredecessorLink><PredecessorUID>1</PredecessorUID><Type>1</Type><LinkLag>0</LinkLag></PredecessorLink></Task>
    <Task><UID>3</UID><Name>Screed</Name><Duration>PT1H0M0S</Duration>
      <PredecessorLink><PredecessorUID>2</PredecessorUID><Type>3</Type><LinkLag>200</LinkLag><LagFormat>7</LagFormat></PredecessorLink></Task>
  </Tasks>
</Project>
XML
# upload FILE QUERY -> body in $TMP/out, status echoed
upload() { curl -sS -o "$TMP/out" -w '%{http_code}' -X POST -H 'content-type: application/xml' \
             --data-binary "@$1" "${CLIENT[@]}" "$BASE_URL/schedules/import$2"; }
[ "$(upload "$TMP/plan.xml" '?default_features=heavy')" = 200 ] || fail "POST /schedules/import -> $(head -c 300 "$TMP/out")"
check '[t["duration"] for t in d["tasks"]] == [120, 90, 60] and d["tasks"][2]["after"] == [{"task": "2", "type": "SS", "lag": 20}] and d["source"]["format"] == "mspdi"' "the MSPDI draft: durations and an SS +20 link"
[ "$(upload "$TMP/plan.xml" '?format=xer')" = 422 ] || fail "an XML file named xer should be 422"
check 'd["detail"][0]["type"] == "wrong_format"' "the wrong format is named"
[ "$(call GET "/runs/$timed_id/schedule?format=mspdi" '' "${CLIENT[@]}")" = 200 ] || fail "schedule as MSPDI"
[ "$(grep -o '<Task>' "$TMP/out" | wc -l)" = 36 ] || fail "the MSPDI has one Task per task"
grep -q '<Assignment>' "$TMP/out" || fail "the MSPDI has no Assignment"
cp "$TMP/out" "$TMP/export.xml"
[ "$(upload "$TMP/export.xml" '?features_field=Text1')" = 200 ] || fail "the export does not import back: $(head -c 300 "$TMP/out")"
check 'len(d["tasks"]) == 36 and len(d["robots"]) >= 1' "the export imports back to its 36 tasks"
echo "smoke: schedule files ok (MSPDI imported; run $timed_id exported as MSPDI and imported back)"
# Webhooks: create (secret shown once), list, refuse a private target, delete. The event
# subscribed to is never emitted by a smoke run, so nothing is sent anywhere.
hook_url="https://hooks.example.com/ltaa-smoke-$$"
code=$(call POST /webhooks "{\"url\":\"$hook_url\",\"events\":[\"run.signed_off\"],\"description\":\"smoke\"}" "${SUPERVISOR[@]}")
[ "$code" = 201 ] || fail "POST /webhooks -> $code $(head -c 300 "$TMP/out")"
check 'd["id"].startswith("wh_") and d["secret"].startswith("whsec_")' "webhook created with a secret"
hook_id=$(python3 -c "import json; print(json.load(open('$TMP/out'))['id'])")
[ "$(call GET /webhooks '' "${SUPERVISOR[@]}")" = 200 ] || fail "GET /webhooks"
check "any(w['id'] == '$hook_id' and 'secret' not in w for w in d)" "webhook listed without its secret"
[ "$(call GET "/webhooks/$hook_id/deliveries" '' "${SUPERVISOR[@]}")" = 200 ] || fail "deliveries"
check 'd == []' "no deliveries for an event never emitted"
code=$(call POST /webhooks '{"url":"http://169.254.169.254/latest/meta-data/","events":["*"]}' "${SUPERVISOR[@]}")
[ "$code" = 422 ] || fail "a link-local webhook target should be 422, got $code"
check 'd["detail"][0]["loc"] == ["body", "url"]' "422 names the url"
[ "$(call DELETE "/webhooks/$hook_id" '' "${SUPERVISOR[@]}")" = 204 ] || fail "DELETE /webhooks/$hook_id"
[ "$(call GET "/webhooks/$hook_id" '' "${SUPERVISOR[@]}")" = 404 ] || fail "deleted webhook should be 404"
echo "smoke: webhooks ok (create, list, deliveries, private target refused, delete)"

# Supervisor reviews and sign-off: the queue is readable, the completed run is signed off
# (the heads signed are verify's), a second run still running cannot be.
[ "$(call GET /reviews '' "${SUPERVISOR[@]}")" = 200 ] || fail "GET /reviews"
check 'isinstance(d, list)' "review queue is a list"
[ "$(call GET "/runs/$run_id/trace/verify" '' "${SUPERVISOR[@]}")" = 200 ] || fail "trace/verify"
heads=$(python3 -c "import json; print(json.dumps(json.load(open('$TMP/out'))['heads'], sort_keys=True))")
# Execution reports and a revision earlier in this script are annotations of this run too.
noted=$(python3 -c "import json; print(json.load(open('$TMP/out'))['annotations'])")
code=$(call POST "/runs/$run_id/signoff" '{"statement":"smoke: plan read and accepted"}' "${SUPERVISOR[@]}")
[ "$code" = 201 ] || fail "POST /runs/$run_id/signoff -> $code $(head -c 300 "$TMP/out")"
check "json.dumps(d['heads'], sort_keys=True) == '$heads' and d['signer']" "sign-off signs verify's heads"
[ "$(call GET "/runs/$run_id/trace/verify" '' "${SUPERVISOR[@]}")" = 200 ] || fail "trace/verify"
check "d['ok'] is True and d['signoffs_ok'] is True and d['annotations'] == $noted + 1" "signed run verifies"
[ "$(call GET "/runs/$run_id" '' "${CLIENT[@]}")" = 200 ] || fail "GET /runs/$run_id"
check 'len(d["signoffs"]) == 1' "sign-off listed on the run"
echo "smoke: reviews and sign-off ok"

if [ -n "${SMOKE_SUPERVISOR_KEY:-}" ]; then
  [ "$(call GET "/runs/$run_id" '')" = 401 ] || fail "no key should be 401"
  [ "$(call GET "/runs/$run_id/trace" '' "${CLIENT[@]}")" = 403 ] || fail "client key on a trace should be 403"
  echo "smoke: access control ok (401 without a key, 403 for a client on the trace)"
fi
# The supervisor console's sign-in page: HTML from the same server, no key needed to see it.
code=$(curl -sS -o "$TMP/out" -D "$TMP/headers" -w '%{http_code}' "$BASE_URL/console/login")
[ "$code" = 200 ] || fail "GET /console/login -> $code"
grep -qi '^content-type: text/html' "$TMP/headers" || fail "/console/login is not HTML"
grep -q 'name="api_key"' "$TMP/out" || grep -q 'Access control is off' "$TMP/out" \
  || fail "/console/login has no api_key field"
echo "smoke: console sign-in page ok"
echo "smoke: all checks passed"
