// The run players of the report (see player.rs): each figure of class "player" holds its run's
// frames as JSON and gets a canvas, play/pause, a speed and a time slider. No network, no library.
// A URL fragment drives it for tests: #player-t=SECONDS shows every player at that time, paused,
// with its robots' positions in the viewport in data-player-robots;
// #player-bench draws 300 frames of the first player, each rasterised, and writes the frame rate
// in data-player-fps on the body element; #player-play plays the first player for 3 s and writes
// the frames shown per second in data-player-play-fps. (No tags in these comments: the tests
// search the DOM.)
(function () {
  'use strict';
  var TRAIL_S = 10;
  var HEIGHT = 440;
  function wrap(a) { return a - 2 * Math.PI * Math.floor((a + Math.PI) / (2 * Math.PI)); }
  function errorColor(e) {
    if (e === null || !isFinite(e)) { return '#9a9a9a'; }
    var u = Math.min(e / 20, 1);
    return 'hsl(' + (130 * (1 - u)).toFixed(0) + ',75%,40%)';
  }
  function Player(root) {
    var data = JSON.parse(root.querySelector('script.player-data').textContent);
    this.root = root;
    this.data = data;
    this.canvas = root.querySelector('canvas');
    this.ctx = this.canvas.getContext('2d');
    this.slider = root.querySelector('input.player-time');
    this.button = root.querySelector('button.player-play');
    this.speed = root.querySelector('select.player-speed');
    this.clock = root.querySelector('output.player-clock');
    this.follow = root.querySelector('input.player-follow');
    if (!data.t || data.t.length === 0) { throw new Error('no frames'); }
    this.t0 = data.t[0];
    this.t1 = data.t[data.t.length - 1];
    this.slider.min = String(this.t0);
    this.slider.max = String(this.t1);
    this.slider.step = 'any';
    // A range input starts at its middle: put it at the first frame, which the clock shows.
    this.slider.value = String(this.t0);
    this.time = this.t0;
    this.playing = false;
    this.last = null;
    this.played = 0;
    this.bounds();
    // Follow the team when its run covers much more ground than the team itself.
    this.follow.checked = (this.hi[0] - this.lo[0]) * (this.hi[1] - this.lo[1]) > 2 * this.span[0] * this.span[1];
    this.resize();
    var self = this;
    this.follow.addEventListener('change', function () { self.resize(); self.publish(); });
    this.button.addEventListener('click', function () { self.toggle(); });
    this.slider.addEventListener('input', function () { self.pause(); self.seek(parseFloat(self.slider.value)); });
    root.addEventListener('keydown', function (event) {
      if (event.key === ' ' && event.target.tagName !== 'BUTTON') { event.preventDefault(); self.toggle(); }
    });
    window.addEventListener('resize', function () { self.resize(); });
  }
  Player.prototype.bounds = function () {
    // The run's bounds, and the largest extent of the team about its centre at any frame.
    var lo = [Infinity, Infinity], hi = [-Infinity, -Infinity], span = [0, 0];
    this.data.pose.forEach(function (row) {
      var flo = [Infinity, Infinity], fhi = [-Infinity, -Infinity];
      for (var i = 0; i + 2 < row.length; i += 3) {
        if (row[i] === null || row[i + 1] === null) { continue; }
        flo[0] = Math.min(flo[0], row[i]); fhi[0] = Math.max(fhi[0], row[i]);
        flo[1] = Math.min(flo[1], row[i + 1]); fhi[1] = Math.max(fhi[1], row[i + 1]);
      }
      if (!isFinite(flo[0])) { return; }
      lo = [Math.min(lo[0], flo[0]), Math.min(lo[1], flo[1])];
      hi = [Math.max(hi[0], fhi[0]), Math.max(hi[1], fhi[1])];
      span = [Math.max(span[0], fhi[0] - flo[0]), Math.max(span[1], fhi[1] - flo[1])];
    });
    if (!isFinite(lo[0])) { lo = [-1, -1]; hi = [1, 1]; }
    var pad = Math.max(0.5, 0.6 * (this.data.d_star || 1));
    this.lo = [lo[0] - pad, lo[1] - pad];
    this.hi = [hi[0] + pad, hi[1] + pad];
    this.span = [1.4 * span[0] + 2 * pad, 1.4 * span[1] + 2 * pad];
  };
  Player.prototype.resize = function () {
    var ratio = window.devicePixelRatio || 1;
    var width = Math.max(200, this.canvas.clientWidth);
    this.canvas.width = Math.round(width * ratio);
    this.canvas.height = Math.round(HEIGHT * ratio);
    this.ratio = ratio;
    this.width = width;
    var extent = this.follow.checked ? this.span : [this.hi[0] - this.lo[0], this.hi[1] - this.lo[1]];
    this.scale = Math.min(width / extent[0], HEIGHT / extent[1]);
    this.draw();
  };
  Player.prototype.px = function (x, y) { return [this.ox + this.scale * x, this.oy - this.scale * y]; };
  // The frame at or before `time` and the fraction of the way to the next one.
  Player.prototype.frameAt = function (time) {
    var t = this.data.t, lo = 0, hi = t.length - 1;
    if (time <= t[0]) { return [0, 0]; }
    if (time >= t[hi]) { return [hi, 0]; }
    while (hi - lo > 1) { var mid = (lo + hi) >> 1; if (t[mid] <= time) { lo = mid; } else { hi = mid; } }
    return [lo, (time - t[lo]) / (t[lo + 1] - t[lo])];
  };
  // Robot poses at `time`, interpolated between frames (null for a robot without a pose).
  Player.prototype.posesAt = function (time) {
    var at = this.frameAt(time), a = this.data.pose[at[0]];
    var b = this.data.pose[Math.min(at[0] + 1, this.data.pose.length - 1)], u = at[1], out = [];
    for (var i = 0; i + 2 < a.length; i += 3) {
      if (a[i] === null || a[i + 1] === null) { out.push(null); continue; }
      var th = a[i + 2] === null ? 0 : a[i + 2];
      if (b[i] === null || b[i + 1] === null || b[i + 2] === null || u === 0) { out.push([a[i], a[i + 1], th]); continue; }
      out.push([a[i] + (b[i] - a[i]) * u, a[i + 1] + (b[i + 1] - a[i + 1]) * u, th + wrap(b[i + 2] - th) * u]);
    }
    return { frame: at[1] < 0.5 ? at[0] : Math.min(at[0] + 1, this.data.t.length - 1), poses: out, index: at[0] };
  };
  // Where the world's origin lands: the team's centre in the middle when following it, else the
  // run's bounds centred.
  Player.prototype.place = function (poses) {
    var scale = this.scale, c = [0, 0], n = 0;
    if (this.follow.checked) {
      poses.forEach(function (p) { if (p) { c[0] += p[0]; c[1] += p[1]; n += 1; } });
      if (n > 0) { this.ox = this.width / 2 - scale * c[0] / n; this.oy = HEIGHT / 2 + scale * c[1] / n; return; }
    }
    this.ox = (this.width - scale * (this.hi[0] - this.lo[0])) / 2 - scale * this.lo[0];
    this.oy = (HEIGHT + scale * (this.hi[1] - this.lo[1])) / 2 + scale * this.lo[1];
  };
  // Grid lines every 0.5, 1, 2, 5, ... m, at least 40 px apart.
  Player.prototype.grid = function () {
    var ctx = this.ctx, step = 0.5;
    while (step * this.scale < 40) { step *= String(step).charAt(0) === '2' ? 2.5 : 2; }
    ctx.strokeStyle = '#eceff1';
    ctx.lineWidth = 1;
    ctx.beginPath();
    var x0 = Math.ceil(-this.ox / this.scale / step) * step, y0 = Math.ceil((this.oy - HEIGHT) / this.scale / step) * step;
    for (var x = x0; this.ox + this.scale * x <= this.width; x += step) {
      var px = Math.round(this.ox + this.scale * x) + 0.5; ctx.moveTo(px, 0); ctx.lineTo(px, HEIGHT);
    }
    for (var y = y0; this.oy - this.scale * y >= 0; y += step) {
      var py = Math.round(this.oy - this.scale * y) + 0.5; ctx.moveTo(0, py); ctx.lineTo(this.width, py);
    }
    ctx.stroke();
  };
  Player.prototype.draw = function () {
    var ctx = this.ctx, data = this.data, self = this, state = this.posesAt(this.time);
    this.place(state.poses);
    ctx.setTransform(this.ratio, 0, 0, this.ratio, 0, 0);
    ctx.fillStyle = '#ffffff';
    ctx.fillRect(0, 0, this.width, HEIGHT);
    this.grid();
    // Trails: each robot's path over the last TRAIL_S seconds.
    var first = this.frameAt(this.time - TRAIL_S)[0];
    ctx.lineWidth = 1.5;
    ctx.globalAlpha = 0.35;
    for (var r = 0; r < state.poses.length; r++) {
      ctx.strokeStyle = data.colors[r % data.colors.length];
      ctx.beginPath();
      var started = false;
      for (var k = first; k <= state.index; k++) {
        var row = data.pose[k];
        if (row[3 * r] === null || row[3 * r + 1] === null) { started = false; continue; }
        var p = this.px(row[3 * r], row[3 * r + 1]);
        if (started) { ctx.lineTo(p[0], p[1]); } else { ctx.moveTo(p[0], p[1]); started = true; }
      }
      if (started && state.poses[r]) { var q = this.px(state.poses[r][0], state.poses[r][1]); ctx.lineTo(q[0], q[1]); }
      ctx.stroke();
    }
    ctx.globalAlpha = 1;
    // The neighbour graph, each edge coloured by its error.
    var edges = data.edges[state.frame], worst = null;
    ctx.lineWidth = 2.5;
    for (var e = 0; e + 2 < edges.length; e += 3) {
      var a = state.poses[edges[e]], b = state.poses[edges[e + 1]], err = edges[e + 2];
      if (!a || !b) { continue; }
      if (err !== null && (worst === null || err > worst)) { worst = err; }
      var pa = this.px(a[0], a[1]), pb = this.px(b[0], b[1]);
      ctx.strokeStyle = errorColor(err);
      ctx.beginPath(); ctx.moveTo(pa[0], pa[1]); ctx.lineTo(pb[0], pb[1]); ctx.stroke();
    }
    // Robots: a triangle along the heading.
    var size = Math.max(9, 0.3 * this.scale);
    ctx.lineWidth = 1;
    ctx.strokeStyle = '#222222';
    state.poses.forEach(function (pose, i) {
      if (!pose) { return; }
      var p = self.px(pose[0], pose[1]), c = Math.cos(pose[2]), s = -Math.sin(pose[2]);
      ctx.fillStyle = data.colors[i % data.colors.length];
      ctx.beginPath();
      ctx.moveTo(p[0] + size * c, p[1] + size * s);
      ctx.lineTo(p[0] - 0.6 * size * c - 0.55 * size * s, p[1] - 0.6 * size * s + 0.55 * size * c);
      ctx.lineTo(p[0] - 0.6 * size * c + 0.55 * size * s, p[1] - 0.6 * size * s - 0.55 * size * c);
      ctx.closePath(); ctx.fill(); ctx.stroke();
    });
    // Scale: a bar of d*.
    var bar = (data.d_star || 1) * this.scale;
    ctx.fillStyle = '#333333'; ctx.fillRect(12, HEIGHT - 16, bar, 3);
    ctx.font = '12px sans-serif'; ctx.fillText('d* = ' + (data.d_star || 1) + ' m', 12, HEIGHT - 22);
    this.clock.textContent = 't = ' + this.time.toFixed(1) + ' s of ' + this.t1.toFixed(1) + ' s · worst edge ' +
      (worst === null ? '–' : worst.toFixed(1) + ' %');
  };
  Player.prototype.seek = function (time) {
    this.time = Math.min(Math.max(time, this.t0), this.t1);
    this.slider.value = String(this.time);
    this.draw();
  };
  Player.prototype.toggle = function () { if (this.playing) { this.pause(); } else { this.play(); } };
  Player.prototype.play = function () {
    var self = this;
    if (this.time >= this.t1) { this.time = this.t0; }
    this.playing = true;
    this.last = null;
    this.button.textContent = 'Pause';
    function tick(now) {
      if (!self.playing) { return; }
      if (self.last !== null) { self.time += (now - self.last) / 1000 * parseFloat(self.speed.value); }
      self.last = now;
      if (self.time >= self.t1) { self.seek(self.t1); self.pause(); return; }
      self.seek(self.time);
      self.played += 1;
      requestAnimationFrame(tick);
    }
    requestAnimationFrame(tick);
  };
  Player.prototype.pause = function () { this.playing = false; this.button.textContent = 'Play'; this.publish(); };
  // The time shown and the robots' positions on screen (CSS px in the viewport), for tests.
  Player.prototype.publish = function () {
    var rect = this.canvas.getBoundingClientRect(), self = this;
    var robots = this.posesAt(this.time).poses.map(function (pose) {
      if (!pose) { return ''; }
      var p = self.px(pose[0], pose[1]);
      return (rect.left + p[0]).toFixed(1) + ',' + (rect.top + p[1]).toFixed(1);
    });
    this.root.setAttribute('data-player-time', this.time.toFixed(3));
    this.root.setAttribute('data-player-slider', parseFloat(this.slider.value).toFixed(3));
    this.root.setAttribute('data-player-robots', robots.join(';'));
    var box = this.root.getBoundingClientRect();
    this.root.setAttribute('data-player-box', [box.left, box.top, box.right, box.bottom].map(function (v) { return v.toFixed(1); }).join(','));
  };
  function bench(player) {
    var n = 300, span = player.t1 - player.t0, start = performance.now();
    for (var k = 0; k < n; k++) {
      player.seek(player.t0 + span * k / (n - 1));
      player.ctx.getImageData(0, 0, 1, 1);
    }
    var ms = performance.now() - start, fps = 1000 * n / ms;
    document.body.setAttribute('data-player-fps', fps.toFixed(1));
    document.body.setAttribute('data-player-bench', n + ' frames of ' + player.data.robots + ' robots over ' +
      span.toFixed(1) + ' s in ' + ms.toFixed(0) + ' ms');
    console.log('formation-report: player ' + fps.toFixed(1) + ' frames/s (' + player.data.robots + ' robots)');
  }
  // Plays `player` at 1x for `ms` of real time and writes the frames it showed per second in
  // data-player-play-fps on the body element (read over the DevTools protocol by
  // scripts/player-fps: a DOM dump would not wait).
  function playFor(player, ms) {
    var start = performance.now();
    player.played = 0;
    player.play();
    setTimeout(function () {
      var fps = 1000 * player.played / (performance.now() - start);
      player.pause();
      document.body.setAttribute('data-player-play-fps', fps.toFixed(1));
    }, ms);
  }
  document.addEventListener('DOMContentLoaded', function () {
    var players = [];
    document.querySelectorAll('figure.player').forEach(function (root) {
      try {
        players.push(new Player(root));
      } catch (error) {
        console.error('a run player could not start: ' + error);
      }
    });
    document.body.setAttribute('data-players', String(players.length));
    if (players.length === 0) { return; }
    var hash = decodeURIComponent(location.hash.slice(1)), at = /^player-t=([0-9.]+)$/.exec(hash);
    if (at) {
      players.forEach(function (p) { p.seek(parseFloat(at[1])); p.publish(); });
    } else if (hash === 'player-bench') {
      bench(players[0]);
    } else if (hash === 'player-play') {
      playFor(players[0], 3000);
    } else {
      players.forEach(function (p) { p.publish(); });
    }
  });
})();
