// The console's only script, for what a server-rendered page cannot do by itself: live
// progress from the run's event stream (EventSource), live status on the runs list, and
// details loaded on demand. Every page works without it.
"use strict";

function watchRun(root) {
  const url = root.dataset.stream;
  if (!url || !window.EventSource) return;
  const total = Number(root.dataset.total);
  const bar = document.getElementById("progress");
  const done = document.getElementById("progress-done");
  const pct = document.getElementById("progress-pct");
  const status = document.getElementById("run-status");
  const events = document.getElementById("events");
  const source = new EventSource(url);
  source.addEventListener("decision", (msg) => {
    const d = JSON.parse(msg.data);
    const allocated = d.task_index + 1;
    bar.value = allocated;
    done.textContent = String(allocated);
    pct.textContent = String(total ? Math.round((100 * allocated) / total) : 100);
  });
  const addEvent = (msg) => {
    const e = JSON.parse(msg.data);
    const item = document.createElement("li");
    const strong = document.createElement("strong");
    strong.textContent = e.kind.replaceAll("_", " ");
    item.append(new Date(e.at).toISOString().replace("T", " ").slice(0, 19) + " UTC ", strong);
    events.append(item);
  };
  source.addEventListener("run", addEvent);
  source.addEventListener("review", addEvent);
  // The server says what the status is (some changes write no event): nothing inferred here.
  const rendered = root.dataset.status;
  const moving = new Set(["queued", "running"]); // progress, not a change of what can be done
  const changed = document.getElementById("status-changed");
  source.addEventListener("status", (msg) => {
    const s = JSON.parse(msg.data);
    status.textContent = s.status.replaceAll("_", " ");
    status.className = "status status-" + s.status;
    // The page's forms (cancel, resume, sign-off) are those of the status it was drawn in.
    if (s.status !== rendered && !(moving.has(s.status) && moving.has(rendered))) {
      document.getElementById("status-now").textContent = s.status.replaceAll("_", " ");
      changed.hidden = false;
    }
    if (s.finished) source.close(); // or EventSource would reconnect to an ended stream
  });
}

function pollRuns(table) {
  const url = table.dataset.poll;
  const body = table.tBodies[0];
  const tick = async () => {
    if (!body.querySelector("tr[data-active]")) return; // nothing left to change
    try {
      const response = await fetch(url, { credentials: "same-origin" });
      if (response.ok) body.innerHTML = await response.text();
    } catch (err) {
      // offline for a moment: try again at the next tick
    }
    setTimeout(tick, 2000);
  };
  setTimeout(tick, 2000);
}

async function loadInto(target, url) {
  target.textContent = "Loading…";
  try {
    const response = await fetch(url, { credentials: "same-origin" });
    target.innerHTML = response.ok ? await response.text() : "Could not load (" + response.status + ").";
  } catch (err) {
    target.textContent = "Could not load: " + err;
  }
}

function wirePrompts() {
  document.addEventListener("click", (event) => {
    const link = event.target.closest("a.load-prompts");
    if (!link) return;
    event.preventDefault();
    const target = document.getElementById(link.dataset.target);
    if (target.dataset.loaded) {
      target.hidden = !target.hidden;
      return;
    }
    target.dataset.loaded = "1";
    loadInto(target, link.getAttribute("href") + "?fragment=1");
  });
}

function wireVerify(box) {
  const link = document.getElementById("verify-link");
  const run = () => loadInto(box, box.dataset.src);
  link.addEventListener("click", (event) => { event.preventDefault(); run(); });
  if (box.hasAttribute("data-auto")) run();
}

document.addEventListener("DOMContentLoaded", () => {
  const run = document.getElementById("run");
  if (run) watchRun(run);
  const runs = document.getElementById("runs");
  if (runs) pollRuns(runs);
  const verify = document.getElementById("verify");
  if (verify) wireVerify(verify);
  // Parts too slow to draw with a large run's page (its frontier, a revision's diff).
  for (const part of document.querySelectorAll("[data-load]")) loadInto(part, part.dataset.load);
  wirePrompts();
});
