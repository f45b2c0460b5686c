/* The paper's experiments (Yildirim, Saeed et al. 2019, Experiments section) on jsPsych.
 *
 * window.LGP_STUDY (config.js, written by python -m stimuli.experiment) says which task
 * this folder runs: "difficulty" or "time" (an online estimation study: instructions,
 * two anchor trials, the trials, a completion screen) or "build" (the lab's Build Task
 * console). Order and counterbalancing: trialOrder below, the same algorithm as
 * stimuli.experiment.trial_order in Python (docs/experiment.md).
 *
 * URL parameters: participant=N (a whole number; the order depends on it), simulated=1
 * (rows are marked SIMULATED: for tests only).
 */
(function () {
  "use strict";
  var S = window.LGP_STUDY;
  var M32 = 4294967296;

  // ------------------------------------------------------------------ order
  function mulberry32(a) {
    return function () {
      var t = (a = (a + 0x6D2B79F5) | 0);
      t = Math.imul(t ^ (t >>> 15), t | 1);
      t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
      return ((t ^ (t >>> 14)) >>> 0) / M32;
    };
  }
  function blockSeed(orderSeed, block) {
    return (Math.imul(orderSeed >>> 0, 0x9E3779B1) + block) >>> 0;
  }
  function unitsOf(trials) {
    var byPair = {}, pairs = [], singles = [], paired = {};
    trials.forEach(function (t) {
      if (t.pair !== null && t.pair !== undefined) { (byPair[t.pair] = byPair[t.pair] || {})[t.level] = t; }
    });
    Object.keys(byPair).map(Number).sort(function (a, b) { return a - b; }).forEach(function (p) {
      if (byPair[p].E && byPair[p].H && Object.keys(byPair[p]).length === 2) {
        pairs.push([byPair[p].E, byPair[p].H]); paired[byPair[p].E.id] = paired[byPair[p].H.id] = true;
      }
    });
    trials.forEach(function (t) { if (!paired[t.id]) singles.push([t]); });
    return { units: pairs.concat(singles), hasPairs: pairs.length > 0 };
  }
  function trialOrder(trials, participant, orderSeed) {
    var u = unitsOf(trials), units = u.units.slice();
    var block = u.hasPairs ? Math.floor(participant / 2) : participant;
    var condition = u.hasPairs ? participant % 2 : 0;
    var draw = mulberry32(blockSeed(orderSeed, block));
    for (var i = units.length - 1; i > 0; i--) {
      var j = Math.floor(draw() * (i + 1)), tmp = units[i]; units[i] = units[j]; units[j] = tmp;
    }
    var easyFirst = {};
    units.filter(function (x) { return x.length === 2; })
      .sort(function (a, b) { return a[0].pair - b[0].pair; })
      .forEach(function (x) { easyFirst[x[0].pair] = (draw() < 0.5) !== (condition === 1); });
    var out = [];
    units.forEach(function (x) {
      var first = "", seq = x;
      if (x.length === 2) { first = easyFirst[x[0].pair] ? "E" : "H"; seq = first === "E" ? x : [x[1], x[0]]; }
      seq.forEach(function (t) {
        out.push(Object.assign({}, t, { position: out.length + 1, condition: condition, first_in_pair: first }));
      });
    });
    return out;
  }
  window.LGP_ORDER = { trialOrder: trialOrder, mulberry32: mulberry32, blockSeed: blockSeed };

  // ------------------------------------------------------------------ participant
  var params = new URLSearchParams(window.location.search);
  var simulated = params.get("simulated") === "1";
  var participant = null, participantSource = "";
  var given = params.get("participant");
  if (given !== null && /^\s*\d{1,9}\s*$/.test(given)) { participant = parseInt(given, 10); participantSource = "url"; }
  if (participant === null && S.task !== "build") {
    var r = new Uint32Array(1); window.crypto.getRandomValues(r);
    participant = r[0] % 1000000; participantSource = "random";
  }

  // ------------------------------------------------------------------ pictures and rows
  function esc(s) { return String(s).replace(/[&<>"]/g, function (c) { return { "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" }[c]; }); }
  function pairHtml(t, startLabel) {
    return '<div class="lgp-pair" data-trial="' + esc(t.id) + '">' +
      '<figure><figcaption>' + (startLabel || "Start") + '</figcaption><img class="lgp-start" src="' + esc(t.start) + '" alt="Start"></figure>' +
      '<figure><figcaption>Finish</figcaption><img class="lgp-finish" src="' + esc(t.finish) + '" alt="Finish"></figure></div>';
  }
  var nMain = S.trials.length;
  var rows = [];
  var t0 = null;
  function baseRow(t, phase, position) {
    return {
      study: S.study, task: S.task, participant: participant, participant_source: participantSource,
      simulated: simulated ? "SIMULATED" : "", condition: t.condition === undefined ? "" : t.condition,
      phase: phase, position: position, trial: t.id, pair: t.pair === null || t.pair === undefined ? "" : t.pair,
      level: t.level || "", first_in_pair: t.first_in_pair || "", response: "", unit: "", rt_ms: "",
      slider_start: "", collapses: "", discarded_ms: "", n_trials: nMain, time_elapsed_ms: "",
      build: S.build, jspsych: S.jspsych
    };
  }
  function csvCell(v) {
    v = v === null || v === undefined ? "" : String(v);
    return /[",\n\r]/.test(v) ? '"' + v.replace(/"/g, '""') + '"' : v;
  }
  function toCsv() {
    var lines = [S.columns.join(",")];
    rows.forEach(function (r) { lines.push(S.columns.map(function (c) { return csvCell(r[c]); }).join(",")); });
    return lines.join("\n") + "\n";
  }
  function fileName() {
    return "lgp-" + S.task + "-" + S.study + "-p" + participant + (simulated ? "-SIMULATED" : "") + ".csv";
  }
  var saved = false;
  function save() {
    var csv = toCsv();
    window.LGP_CSV = csv;
    if (typeof window.LGP_SAVE === "function") { window.LGP_SAVE(csv, fileName(), rows); }   // a server's own hook
    if (S.jatos && typeof jatos !== "undefined") { jatos.submitResultData(csv); return; }  // JATOS keeps the result
    if (!saved) { download(csv); saved = true; }
  }
  function download(csv) {
    var blob = new Blob([csv], { type: "text/csv" });
    var a = document.createElement("a");
    a.href = URL.createObjectURL(blob); a.download = fileName();
    document.body.appendChild(a); a.click(); document.body.removeChild(a);
  }
  window.LGP_DOWNLOAD = function () { download(toCsv()); };

  var jsPsych = initJsPsych({
    on_finish: function () { /* saved by the completion screen's on_start */ }
  });
  window.LGP_JSPSYCH = jsPsych;
  var preload = {
    type: jsPsychPreload,
    images: S.trials.concat(S.anchors).reduce(function (a, t) { return a.concat([t.start, t.finish]); }, []),
    message: "Loading the pictures...",
    show_progress_bar: true,
    on_finish: function (data) { window.LGP_PRELOAD_FAILED = data.failed_images || []; t0 = performance.now(); }
  };

  // ------------------------------------------------------------------ estimation tasks
  function sliderTrial(t, phase, position) {
    var sl = S.slider;
    var ask = S.task === "time" ? "Move the slider to your estimate." : "Move the slider to answer.";
    var labels = '<div class="lgp-labels" aria-hidden="true">' +
      sl.labels.map(function (l) { return "<span>" + esc(l) + "</span>"; }).join("") + "</div>";
    return {
      type: jsPsychHtmlSliderResponse,
      stimulus: pairHtml(t) + '<p class="lgp-question" id="lgp-question">' + esc(S.question) + "</p>",
      // The end labels are drawn by us (.lgp-labels, a flex row under the slider): the
      // plugin's absolutely placed label boxes reach past a narrow window's edge.
      labels: [], min: sl.min, max: sl.max, slider_start: sl.start, step: sl.step,
      require_movement: true, slider_width: null, button_label: "Next",
      prompt: labels + '<p class="lgp-value" id="lgp-value" aria-live="polite">' + ask + "</p>",
      data: { lgp_trial: t.id, lgp_phase: phase },
      on_load: function () {
        var input = document.querySelector("#jspsych-html-slider-response-response");
        var out = document.getElementById("lgp-value");
        var next = document.querySelector("#jspsych-html-slider-response-next");
        input.setAttribute("aria-labelledby", "lgp-question");
        input.setAttribute("aria-valuetext", sl.labels.join(" to "));
        // Answered: a tap or click on the slider (even on its thumb, keeping the
        // middle), a drag, or an arrow key (input/change). Next is enabled and
        // "Move the slider ..." goes away (the time task shows the estimate instead).
        function answered() {
          next.disabled = false;
          if (S.task === "time") {
            var s = parseInt(input.value, 10);
            out.textContent = "about " + (s >= 60 ? Math.floor(s / 60) + " min " + (s % 60) + " s" : s + " s");
            out.className = "lgp-value lgp-shown";
          } else {
            out.className = "lgp-value lgp-answered";
          }
        }
        ["pointerdown", "touchstart", "mousedown", "input", "change"].forEach(function (ev) {
          input.addEventListener(ev, answered, { passive: true });
        });
        input.addEventListener("keydown", function (e) {
          if (/^(Arrow|Page|Home|End)/.test(e.key)) { answered(); }
        });
      },
      on_finish: function (data) {
        var row = baseRow(t, phase, position);
        row.response = data.response; row.unit = sl.unit; row.rt_ms = Math.round(data.rt);
        row.slider_start = data.slider_start; row.time_elapsed_ms = Math.round(performance.now() - t0);
        rows.push(row);
      }
    };
  }
  function estimationTimeline() {
    var order = trialOrder(S.trials, participant, S.order_seed);
    window.LGP_ORDER_SHOWN = order.map(function (t) { return t.id; });
    var what = S.task === "time"
      ? "For each, estimate <b>how long it would take to make</b> the Finish structure from the Start blocks, in seconds, on the slider."
      : "For each, judge <b>how difficult it would be</b> to make the Finish structure from the Start blocks, on the slider from very easy to very difficult.";
    var intro = {
      type: jsPsychInstructions, show_clickable_nav: true, button_label_next: "Next", button_label_previous: "Back",
      pages: [
        '<div class="lgp-text"><h2>Building with blocks</h2><p>You will see pairs of pictures of ' +
        "1-inch wooden blocks on a table. The left picture, <b>Start</b>, shows the blocks as they lie at the start. " +
        "The right picture, <b>Finish</b>, shows a structure someone would build from them.</p>" +
        "<p>" + what + "</p><p>There are no right or wrong answers; please use the whole range of the slider.</p></div>",
        '<div class="lgp-text"><p>First come two examples to show the range: one very easy and one very hard. ' +
        "Answer them like every other.</p><p>Then come " + nMain + " more. Press Next to begin.</p></div>"
      ]
    };
    var tl = [preload, intro];
    S.anchors.forEach(function (a, k) { tl.push(sliderTrial(a, "anchor", k + 1)); });
    order.forEach(function (t) { tl.push(sliderTrial(t, "main", t.position)); });
    tl.push(completion());
    return tl;
  }
  function completion() {
    return {
      type: jsPsychHtmlButtonResponse,
      on_start: function () { save(); },
      stimulus: function () {
        return '<div class="lgp-text" id="lgp-done"><h2>Thank you!</h2><p>You have finished. ' +
          (S.jatos && typeof jatos !== "undefined" ? "Your answers have been sent." :
            "Your answers were saved as a CSV file (" + esc(fileName()) + ") in your downloads; " +
            'the button below saves them again.</p><p class="lgp-note">' + rows.length + " responses recorded.") + "</p></div>";
      },
      choices: function () { return [S.jatos && typeof jatos !== "undefined" ? "Finish" : "Save the answers again"]; },
      on_finish: function () {
        if (S.jatos && typeof jatos !== "undefined") { jatos.endStudy(); } else { window.LGP_DOWNLOAD(); }
      },
      response_ends_trial: true
    };
  }

  // ------------------------------------------------------------------ build console
  function keysHtml(list) {
    return '<p class="lgp-keys">' + list.map(function (k) { return "<kbd>" + k[0] + "</kbd> " + k[1]; }).join(" &nbsp; ") + "</p>";
  }
  function buildTimeline() {
    var tl = [preload];
    var order = null;
    if (participant === null) {
      var entered = "";
      tl.push({
        type: jsPsychHtmlButtonResponse,
        stimulus: '<div class="lgp-text"><h2>Build task</h2><p>Participant number: <input id="lgp-participant" ' +
          'inputmode="numeric" pattern="[0-9]*" autofocus></p><p class="lgp-note">A whole number; it sets the order ' +
          "of the trials (docs/experiment.md).</p></div>",
        choices: ["Start"],
        on_load: function () {
          var box = document.getElementById("lgp-participant"), btn = document.querySelector(".jspsych-btn");
          btn.disabled = true;
          box.addEventListener("input", function () { entered = box.value.trim(); btn.disabled = !/^\d{1,9}$/.test(entered); });
        },
        on_finish: function () { participant = parseInt(entered, 10); participantSource = "entered"; }
      });
    }
    tl.push({
      type: jsPsychHtmlKeyboardResponse, choices: [" "],
      stimulus: function () {
        order = trialOrder(S.trials, participant, S.order_seed);
        window.LGP_ORDER_SHOWN = order.map(function (t) { return t.id; });
        return '<div class="lgp-text"><h2>Build task: participant ' + participant + "</h2><p>For each trial: lay the blocks " +
          "out as in <b>Start</b>; press <kbd>Space</kbd> when the participant starts building and <kbd>Space</kbd> again " +
          "when the <b>Finish</b> structure stands. If it collapses and must be started again, press <kbd>R</kbd>: the " +
          "attempt is recorded and the trial begins again from the Start layout.</p><p>" + nMain + " trials. Press " +
          "<kbd>Space</kbd> to show the first.</p></div>";
      }
    });
    for (var k = 0; k < nMain; k++) { tl.push(buildTrial(k, function () { return order; })); }
    tl.push(completion());
    return tl;
  }
  function buildTrial(k, getOrder) {
    var collapses = 0, discarded = 0, last = null;
    var layout = {
      type: jsPsychHtmlKeyboardResponse, choices: [" "],
      stimulus: function () {
        var t = getOrder()[k];
        return '<p class="lgp-console-status">Trial ' + (k + 1) + " of " + nMain + " (" + esc(t.id) + ")" +
          (collapses ? " &mdash; restart " + collapses : "") + ": lay out the Start state</p>" + pairHtml(t) +
          keysHtml([["Space", "the participant starts: start the clock"]]);
      }
    };
    var building = {
      type: jsPsychHtmlKeyboardResponse, choices: [" ", "r"],
      stimulus: function () {
        var t = getOrder()[k];
        return '<p class="lgp-console-status">Trial ' + (k + 1) + " of " + nMain + " (" + esc(t.id) + "): building</p>" +
          '<div class="lgp-clock" id="lgp-clock">0.0 s</div>' + pairHtml(t) +
          keysHtml([["Space", "finished: stop the clock"], ["R", "collapsed: record and restart"]]);
      },
      on_load: function () {
        var start = performance.now(), el = document.getElementById("lgp-clock");
        building.timer = setInterval(function () { if (el) { el.textContent = ((performance.now() - start) / 1000).toFixed(1) + " s"; } }, 100);
      },
      on_finish: function (data) {
        clearInterval(building.timer);
        last = data.response;
        if (data.response === "r") { collapses += 1; discarded += data.rt; return; }
        var t = getOrder()[k];
        var row = baseRow(t, "main", t.position);
        row.response = (data.rt / 1000).toFixed(3); row.unit = "s"; row.rt_ms = Math.round(data.rt);
        row.collapses = collapses; row.discarded_ms = Math.round(discarded);
        row.time_elapsed_ms = Math.round(performance.now() - t0);
        rows.push(row);
      }
    };
    return { timeline: [layout, building], loop_function: function () { return last === "r"; } };
  }

  window.addEventListener("load", function () {
    jsPsych.run(S.task === "build" ? buildTimeline() : estimationTimeline());
  });
})();
