// The 3D view of report.html and verify.html (three.js r111 from Debian's libjs-three, inlined). The
// data is the JSON of postproc/viewer.cpp: meshes as base64 little-endian Float32/Uint32 arrays,
// deviation bands as bytes, the tools' meridians (z, r) from the tip, the programs' frames.
// URL hash: #track=K&pose=N&marker=M&colour=all|P|cK&hide=envelope,ruled,path,part,tool&machine=1&view=only
// (colour: all, patch P, or further colouring K such as one verified program; marker: jump to the
// worst pose of collision M; machine=1: the machine moving; view=only: the view alone, for screenshots).
(function () {
  'use strict';
  var fail = window.flankcamViewerFail;
  try {
    var data = JSON.parse(document.getElementById('fcv-data').textContent);
    var bytes = function (b64) {
      var s = atob(b64), u = new Uint8Array(s.length);
      for (var i = 0; i < s.length; ++i) u[i] = s.charCodeAt(i);
      return u;
    };
    var f32 = function (b64) { return new Float32Array(bytes(b64).buffer); };
    var u32 = function (b64) { return new Uint32Array(bytes(b64).buffer); };
    var params = {};
    location.hash.replace(/^#/, '').split('&').forEach(function (kv) {
      var p = kv.split('=');
      if (p[0]) params[decodeURIComponent(p[0])] = decodeURIComponent(p[1] || '');
    });
    if (params.view === 'only') document.body.classList.add('fcv-only');

    var canvas = document.getElementById('fcv-canvas');
    var renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: true, preserveDrawingBuffer: true });
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.setClearColor(0xf4f6f9, 1);
    var scene = new THREE.Scene();
    var camera = new THREE.PerspectiveCamera(35, 1, 0.1, 1000);
    camera.up.set(0, 0, 1);  // machine convention: Z up
    scene.add(new THREE.AmbientLight(0xffffff, 0.55));
    var light = new THREE.DirectionalLight(0xffffff, 0.55);
    light.position.set(0.3, 0.5, 1);
    camera.add(light);
    scene.add(camera);

    var meshGeometry = function (m) {
      var g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.BufferAttribute(f32(m.positions), 3));
      g.setIndex(new THREE.BufferAttribute(u32(m.indices), 1));
      g.computeVertexNormals();
      g.computeBoundingSphere();
      return g;
    };
    var vertexColors = THREE.VertexColors !== undefined ? THREE.VertexColors : true;
    var translucent = function (color, opacity) {
      return new THREE.MeshLambertMaterial({ color: color, transparent: true, opacity: opacity, side: THREE.DoubleSide,
                                             depthWrite: false });
    };

    // Φ coloured by its deviation band (viewer.h DeviationBand: none, within, over, under).
    var bandColour = [[0.667, 0.667, 0.667], [0.235, 0.667, 0.314], [0.157, 0.314, 0.843], [0.843, 0.157, 0.157]];
    var surfaceGeometry = meshGeometry(data.surface);
    var nv = data.surface.vertices;
    var colours = new Float32Array(3 * nv);
    surfaceGeometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
    var paint = function (b64) {
      var b = bytes(b64);
      for (var i = 0; i < nv; ++i) {
        var c = bandColour[b[i]] || bandColour[0];
        colours[3 * i] = c[0]; colours[3 * i + 1] = c[1]; colours[3 * i + 2] = c[2];
      }
      surfaceGeometry.attributes.color.needsUpdate = true;
    };
    var surface = new THREE.Mesh(surfaceGeometry, new THREE.MeshLambertMaterial({ vertexColors: vertexColors,
                                                                                 side: THREE.DoubleSide }));
    // Everything attached to the part: in machine mode the tables turn it (work.matrix).
    var work = new THREE.Group();
    work.matrixAutoUpdate = false;
    scene.add(work);
    work.add(surface);
    var centre = surfaceGeometry.boundingSphere.center.clone(), radius = surfaceGeometry.boundingSphere.radius;

    var partLayer = new THREE.Group(), envelopeLayer = new THREE.Group(), ruledLayer = new THREE.Group();
    var pathLayer = new THREE.Group(), toolLayer = new THREE.Group(), markerLayer = new THREE.Group();
    [partLayer, envelopeLayer, ruledLayer, pathLayer, markerLayer].forEach(function (l) { work.add(l); });
    scene.add(toolLayer);
    if (data.part) partLayer.add(new THREE.Mesh(meshGeometry(data.part), translucent(0x8899aa, 0.22)));

    // Per patch: envelope Ω, the axis ruled surface, the tool assembly revolved from its meridians.
    var tools = [];
    var sideSum = new THREE.Vector3();
    data.patches.forEach(function (p) {
      if (p.envelope) {
        // Pushed back in depth: where Ω and Φ coincide Φ's bands show, Ω shows where it leaves Φ.
        var em = translucent(0xd8b840, 0.3);
        em.polygonOffset = true;
        em.polygonOffsetFactor = 2;
        em.polygonOffsetUnits = 4;
        var e = new THREE.Mesh(meshGeometry(p.envelope), em);
        e.renderOrder = 1;
        envelopeLayer.add(e);
      }
      var r = f32(p.rails), n = p.poses;
      if (n >= 2) {
        var g = new THREE.BufferGeometry(), idx = [];
        g.setAttribute('position', new THREE.BufferAttribute(r, 3));
        for (var i = 0; i + 1 < n; ++i) idx.push(2 * i, 2 * i + 2, 2 * i + 3, 2 * i, 2 * i + 3, 2 * i + 1);
        g.setIndex(idx);
        g.computeVertexNormals();
        // Faint: it lies between the tool side and Φ. Rails and a few rulings carry its shape.
        var ruled = new THREE.Mesh(g, translucent(0x9a5cd0, 0.12));
        ruled.renderOrder = 2;
        ruledLayer.add(ruled);
        var rails = [new THREE.BufferGeometry(), new THREE.BufferGeometry()];
        for (var k = 0; k < 2; ++k) {
          var pts = new Float32Array(3 * n);
          for (var j = 0; j < n; ++j) for (var c = 0; c < 3; ++c) pts[3 * j + c] = r[6 * j + 3 * k + c];
          rails[k].setAttribute('position', new THREE.BufferAttribute(pts, 3));
          ruledLayer.add(new THREE.Line(rails[k], new THREE.LineBasicMaterial({ color: 0x6a2ca0 })));
        }
        var every = Math.max(1, Math.round(n / 6)), rulings = [];
        for (var q = 0; q < n; q += every) for (var c2 = 0; c2 < 6; ++c2) rulings.push(r[6 * q + c2]);
        var rg = new THREE.BufferGeometry();
        rg.setAttribute('position', new THREE.BufferAttribute(new Float32Array(rulings), 3));
        ruledLayer.add(new THREE.LineSegments(rg, new THREE.LineBasicMaterial({ color: 0x6a2ca0 })));
        for (var m = 0; m < n; ++m)
          sideSum.add(new THREE.Vector3(0.5 * (r[6 * m] + r[6 * m + 3]), 0.5 * (r[6 * m + 1] + r[6 * m + 4]),
                                        0.5 * (r[6 * m + 2] + r[6 * m + 5])).sub(centre));
      }
      var tool = new THREE.Group();
      var lathe = function (zr, color) {
        if (zr.length < 2) return;
        var pts = [new THREE.Vector2(0, zr[0][0])];
        zr.forEach(function (q) { pts.push(new THREE.Vector2(Math.max(q[1], 1e-6), q[0])); });
        pts.push(new THREE.Vector2(0, zr[zr.length - 1][0]));
        tool.add(new THREE.Mesh(new THREE.LatheBufferGeometry(pts, 48),
                                new THREE.MeshLambertMaterial({ color: color, side: THREE.DoubleSide })));
      };
      lathe(p.cutter, 0xe09a30);
      lathe(p.shank, 0x9aa0a8);
      lathe(p.holder, 0x4a5a6e);
      tool.visible = false;
      toolLayer.add(tool);
      tools.push(tool);
    });

    // Markers: collisions and gouges, each jumps to its worst pose.
    var markerSize = 0.018 * radius;
    var markerList = document.getElementById('fcv-markers');
    var jumps = [];
    data.patches.forEach(function (p) {
      p.markers.forEach(function (mk) {
        // Drawn over everything: the tool at the marker's pose stands where the marker is.
        var s = new THREE.Mesh(new THREE.SphereBufferGeometry(markerSize, 16, 12),
                               new THREE.MeshBasicMaterial({ color: 0xff2060, depthTest: false }));
        s.renderOrder = 10;
        s.position.set(mk.at[0], mk.at[1], mk.at[2]);
        markerLayer.add(s);
        var b = document.createElement('button');
        b.type = 'button';
        b.textContent = mk.label;
        b.addEventListener('click', function () { jump(mk); });
        markerList.appendChild(b);
        jumps.push(mk);
      });
    });

    // Tracks: the posted programs (and fitted poses of patches without one).
    var tracks = data.tracks.map(function (t) {
      return { name: t.name, axes: t.axes, hasValues: t.has_values, n: t.frames, tip: f32(t.tip), axis: f32(t.axis),
               values: f32(t.values), rapid: bytes(t.rapid), patch: u32(t.patch), line: u32(t.line) };
    });
    var trackSelect = document.getElementById('fcv-track'), colourSelect = document.getElementById('fcv-colour');
    var slider = document.getElementById('fcv-slider'), frameLabel = document.getElementById('fcv-frame');
    var readout = document.getElementById('fcv-readout'), playButton = document.getElementById('fcv-play');
    tracks.forEach(function (t, i) {
      var o = document.createElement('option');
      o.value = i;
      o.textContent = t.name + ' (' + t.n + ' poses)';
      trackSelect.appendChild(o);
    });
    var addColour = function (value, label) {
      var o = document.createElement('option');
      o.value = value;
      o.textContent = label;
      colourSelect.appendChild(o);
    };
    addColour('all', data.combined);
    data.patches.forEach(function (p, i) { if (p.bands !== null) addColour(String(i), p.name); });
    if (data.colourings.length > 1 || data.patches.some(function (p) { return p.bands !== null; }))  // else one is 'all'
      data.colourings.forEach(function (c, i) { addColour('c' + i, c.name); });
    var setColour = function (v) {
      var c = /^c\d+$/.test(v) ? data.colourings[parseInt(v.slice(1), 10)] : undefined;
      var i = parseInt(v, 10), p = /^\d+$/.test(v) && i < data.patches.length ? data.patches[i] : undefined;
      var bands = c ? c.bands : p && p.bands !== null ? p.bands : null;
      paint(bands !== null ? bands : data.bands);
      colourSelect.value = bands !== null ? v : 'all';
    };

    // Machine mode: the machine's chain (data.machine, as kinematics/kinematics.cpp applies it:
    // rotary[0] outermost; tables about points in part coordinates, heads about points relative to
    // the tip at zero angles, gauge length + tool length below the head pivot) moved by a frame's
    // programmed rotary values. Bodies: the inner table a disc under the part, an outer table a
    // cradle, each head axis a box along its axis, the spindle housing above the holder.
    var yAxis = new THREE.Vector3(0, 1, 0);  // the axis of three.js's lathes, cylinders and the tool
    var machine = data.machine, machineBox = document.getElementById('fcv-machine');
    var machineLayer = new THREE.Group();
    machineLayer.visible = false;
    scene.add(machineLayer);
    var v3 = function (a) { return new THREE.Vector3(a[0], a[1], a[2]); };
    var turn = function (centre, dir, deg) {  // deg about the line through centre along dir
      var m = new THREE.Matrix4().makeTranslation(centre.x, centre.y, centre.z);
      m.multiply(new THREE.Matrix4().makeRotationAxis(dir.clone().normalize(), deg * Math.PI / 180));
      return m.multiply(new THREE.Matrix4().makeTranslation(-centre.x, -centre.y, -centre.z));
    };
    var fixed = function (body) { body.matrixAutoUpdate = false; machineLayer.add(body); return body; };
    // A box or cylinder with its long side along `dir`, centred at `at`.
    var solid = function (geometry, at, dir, colour) {
      var m = new THREE.Mesh(geometry, new THREE.MeshLambertMaterial({ color: colour }));
      m.position.copy(at);
      m.quaternion.setFromUnitVectors(yAxis, dir.clone().normalize());
      return m;
    };
    var tableBodies = [], headSets = [];
    if (machine) {
      var solidPart = data.part ? data.part : data.surface, pp = f32(solidPart.positions);
      var tableAxes = [0, 1].filter(function (k) { return machine.rotary[k].table; });
      var headAxes = [0, 1].filter(function (k) { return !machine.rotary[k].table; });
      var inner = tableAxes.length ? tableAxes[tableAxes.length - 1] : -1, discCentre = null, discR = radius;
      tableAxes.slice().reverse().forEach(function (k) {
        var ax = machine.rotary[k], c = v3(ax.pivot), d = v3(ax.direction).normalize(), body = new THREE.Group();
        if (k === inner) {  // the rotary table carrying the part: a disc under it, as wide as it
          var u = d.clone();
          if (u.z < 0) u.negate();
          var smin = Infinity, rmax = 0, x = new THREE.Vector3();
          for (var i = 0; i < pp.length; i += 3) {
            x.set(pp[i], pp[i + 1], pp[i + 2]).sub(c);
            var along = x.dot(u);
            smin = Math.min(smin, along);
            rmax = Math.max(rmax, x.addScaledVector(u, -along).length());
          }
          discR = 1.1 * rmax;
          var h = 0.12 * discR;
          discCentre = c.clone().addScaledVector(u, smin - 0.5 * h - 0.02 * discR);
          body.add(solid(new THREE.CylinderBufferGeometry(discR, discR, h, 48), discCentre, u, 0x7d8a99));
        } else {  // an outer table: a cradle turning about its axis, cheeks up to the inner table
          var reach = discCentre ? discCentre.clone().sub(c) : new THREE.Vector3(0, 0, discR);
          var w = reach.clone().addScaledVector(d, -reach.dot(d));
          var half = 1.25 * discR, wl = w.length();
          if (wl < 1e-6) w.set(0, 0, 1).addScaledVector(d, -d.z).normalize(), wl = 0.3 * discR;
          else w.normalize();
          var n = new THREE.Vector3().crossVectors(d, w);
          // A box with its x, y, z sides along d, w, n.
          var block = function (sx, sy, sz, at) {
            var m = new THREE.Mesh(new THREE.BoxBufferGeometry(sx, sy, sz), new THREE.MeshLambertMaterial({ color: 0x5f6b7a }));
            m.quaternion.setFromRotationMatrix(new THREE.Matrix4().makeBasis(d, w, n));
            m.position.copy(at);
            return m;
          };
          body.add(solid(new THREE.CylinderBufferGeometry(0.12 * discR, 0.12 * discR, 2 * half, 24), c, d, 0x5f6b7a));
          [-1, 1].forEach(function (side) {
            body.add(block(0.15 * discR, wl + 0.3 * discR, 0.5 * discR, c.clone().addScaledVector(d, side * half).addScaledVector(w, 0.5 * wl)));
          });
          body.add(block(2 * half, 0.1 * discR, 1.6 * discR, c.clone().addScaledVector(w, wl - 0.25 * discR)));
        }
        tableBodies[k] = fixed(body);
      });
      // Head bodies per patch (tool length and holder size differ), in the tool frame at zero angles.
      data.patches.forEach(function (p, n) {
        var L = machine.tool_length_mm[n], s = v3(machine.spindle).normalize(), set = { axes: [], housing: null };
        var zr = p.holder.length ? p.holder : p.shank.length ? p.shank : p.cutter;
        var top = zr[zr.length - 1][0], dh = 0;
        zr.forEach(function (q) { dh = Math.max(dh, 2 * q[1]); });
        var pivotZ = machine.gauge_length_mm + L, z1 = Math.max(pivotZ, top + 1.5 * dh);
        set.housing = fixed(new THREE.Group());
        set.housing.add(solid(new THREE.CylinderBufferGeometry(0.6 * dh, 0.6 * dh, z1 - top, 32),
                              s.clone().multiplyScalar(0.5 * (top + z1)), s, 0x59626e));
        headAxes.forEach(function (k) {
          var ax = machine.rotary[k], centre = v3(ax.pivot).addScaledVector(s, pivotZ);
          var g = fixed(new THREE.Group());
          g.add(solid(new THREE.BoxBufferGeometry(1.1 * dh, 1.6 * dh, 1.1 * dh), centre, v3(ax.direction), 0x48505a));
          set.axes[k] = { body: g, centre: centre, direction: v3(ax.direction) };
        });
        headSets.push(set);
      });
    }
    var machineMode = false;
    // Places the tables, the part with them, and the head bodies of `patch` for frame i of track t;
    // turns `tip` and `axis` (part frame) into the machine frame. Off (or CL-data): the part frame.
    var placeMachine = function (t, i, patch, tip, axis) {
      machineLayer.visible = machineMode && t.hasValues;
      work.matrix.identity();
      work.matrixWorldNeedsUpdate = true;
      if (!machineLayer.visible) return;
      headSets.forEach(function (set, n) {
        set.housing.visible = n === patch;
        set.axes.forEach(function (a) { if (a) a.body.visible = n === patch; });
      });
      var deg = [t.values[5 * i + 3], t.values[5 * i + 4]], table = new THREE.Matrix4();
      for (var k = 0; k < 2; ++k) {  // outer first: x -> T0(T1(x)); a body turns with the axes outside it
        if (!machine.rotary[k].table) continue;
        table.multiply(turn(v3(machine.rotary[k].pivot), v3(machine.rotary[k].direction), deg[k]));
        tableBodies[k].matrix.copy(table);
        tableBodies[k].matrixWorldNeedsUpdate = true;
      }
      work.matrix.copy(table);
      tip.applyMatrix4(table);
      axis.transformDirection(table);
      var set = headSets[patch];
      if (!set) return;
      var head = new THREE.Matrix4(), partial = [];
      for (var j = 0; j < 2; ++j) {
        if (!set.axes[j]) continue;
        head.multiply(turn(set.axes[j].centre, set.axes[j].direction, deg[j]));
        partial[j] = head.clone();
      }
      // The controlled point: the machine tip less the head chain's image of the tip (forward()).
      var base = tip.clone().sub(new THREE.Vector3().applyMatrix4(head));
      var shift = new THREE.Matrix4().makeTranslation(base.x, base.y, base.z);
      set.axes.forEach(function (a, j) {
        if (!a) return;
        a.body.matrix.multiplyMatrices(shift, partial[j]);
        a.body.matrixWorldNeedsUpdate = true;
      });
      set.housing.matrix.multiplyMatrices(shift, head);
      set.housing.matrixWorldNeedsUpdate = true;
    };

    var current = { track: 0, frame: 0 };
    var pathLine = null;
    var fmt3 = function (x) { return x.toFixed(3); };
    var render = function () { renderer.render(scene, camera); };
    var showFrame = function (i) {
      var t = tracks[current.track];
      if (!t || t.n === 0) { readout.textContent = 'no poses'; return; }
      i = Math.max(0, Math.min(t.n - 1, i | 0));
      current.frame = i;
      slider.value = i;
      var patch = t.patch[i];
      tools.forEach(function (g, k) { g.visible = k === patch; });
      var tool = tools[patch];
      var tip = new THREE.Vector3(t.tip[3 * i], t.tip[3 * i + 1], t.tip[3 * i + 2]);
      var axis = new THREE.Vector3(t.axis[3 * i], t.axis[3 * i + 1], t.axis[3 * i + 2]).normalize();
      placeMachine(t, i, patch, tip, axis);
      if (tool) {
        tool.position.copy(tip);
        tool.quaternion.setFromUnitVectors(yAxis, axis);
      }
      frameLabel.textContent = 'pose ' + (i + 1) + ' / ' + t.n;
      var words = [];
      if (t.hasValues) for (var a = 0; a < 5; ++a) words.push(t.axes[a] + ' ' + fmt3(t.values[5 * i + a]));
      readout.textContent = (data.patches[patch] ? data.patches[patch].name : '') + ' \u00b7 ' +
                            (t.line[i] > 0 ? 'line ' + t.line[i] + ' \u00b7 ' : '') +
                            (t.rapid[i] ? 'rapid' : 'feed') + ' \u00b7 ' +
                            (t.hasValues ? 'programmed ' + words.join('  ')
                                         : t.line[i] > 0 ? 'CL-data, no machine axes' : 'fitted pose, no program (it collides)') +
                            ' \u00b7 tip ' + fmt3(t.tip[3 * i]) + ', ' + fmt3(t.tip[3 * i + 1]) + ', ' + fmt3(t.tip[3 * i + 2]) + ' mm' +
                            (machineLayer.visible ? ' \u00b7 machine frame tip ' + fmt3(tip.x) + ', ' + fmt3(tip.y) + ', ' + fmt3(tip.z) + ' mm' : '');
      render();
    };
    var setTrack = function (k) {
      k = Math.max(0, Math.min(tracks.length - 1, k | 0));
      current.track = k;
      trackSelect.value = k;
      var t = tracks[k];
      if (pathLine) { pathLayer.remove(pathLine); pathLine.geometry.dispose(); }
      if (!t) return;
      slider.max = Math.max(0, t.n - 1);
      var g = new THREE.BufferGeometry(), col = new Float32Array(3 * t.n);
      for (var i = 0; i < t.n; ++i) {
        var c = t.rapid[i] ? [1, 0.55, 0.1] : [0.12, 0.16, 0.25];
        col[3 * i] = c[0]; col[3 * i + 1] = c[1]; col[3 * i + 2] = c[2];
      }
      g.setAttribute('position', new THREE.BufferAttribute(t.tip, 3));
      g.setAttribute('color', new THREE.BufferAttribute(col, 3));
      pathLine = new THREE.Line(g, new THREE.LineBasicMaterial({ vertexColors: vertexColors }));
      pathLayer.add(pathLine);
    };
    var jump = function (mk) {
      var k = mk.frames[current.track] >= 0 ? current.track : mk.frames.findIndex(function (f) { return f >= 0; });
      if (k < 0) return;
      if (k !== current.track) setTrack(k);
      showFrame(mk.frames[k]);
    };

    // Camera: on the tool's side of Φ, a little above, the whole surface in view.
    var normal = new THREE.Vector3(), pos = surfaceGeometry.attributes.position.array, ix = surfaceGeometry.index.array;
    var va = new THREE.Vector3(), vb = new THREE.Vector3(), vc = new THREE.Vector3();
    for (var f = 0; f < ix.length; f += 3) {
      va.fromArray(pos, 3 * ix[f]); vb.fromArray(pos, 3 * ix[f + 1]); vc.fromArray(pos, 3 * ix[f + 2]);
      normal.add(vb.sub(va).cross(vc.sub(va)));
    }
    if (normal.lengthSq() === 0) normal.set(1, 0, 0);
    if (sideSum.lengthSq() === 0 && tracks.length > 0) {  // no fitted poses (verify.html): the tool's side from the motion
      var t0 = tracks[0];
      for (var s0 = 0; s0 < t0.n; ++s0)
        if (!t0.rapid[s0]) sideSum.add(new THREE.Vector3(t0.tip[3 * s0], t0.tip[3 * s0 + 1], t0.tip[3 * s0 + 2]).sub(centre));
    }
    normal.normalize();
    if (sideSum.dot(normal) < 0) normal.negate();
    // Turned 20 degrees about Z so the tool does not hide the surface it cuts.
    var view = normal.clone().applyAxisAngle(new THREE.Vector3(0, 0, 1), 0.35).add(new THREE.Vector3(0, 0, 0.35)).normalize();
    var far = radius * 3.8;
    camera.position.copy(centre).addScaledVector(view, far);
    camera.near = radius * 0.01;
    camera.far = radius * 20;
    var controls = new THREE.OrbitControls(camera, canvas);
    controls.target.copy(centre);
    controls.screenSpacePanning = true;
    controls.addEventListener('change', render);
    controls.update();

    var resize = function () {
      var w = canvas.clientWidth || 800, h = canvas.clientHeight || 600;
      renderer.setSize(w, h, false);
      camera.aspect = w / h;
      camera.updateProjectionMatrix();
      render();
    };
    window.addEventListener('resize', resize);

    var playing = null;
    var stop = function () { if (playing) clearInterval(playing); playing = null; playButton.textContent = 'Play'; };
    playButton.addEventListener('click', function () {
      if (playing) { stop(); return; }
      var t = tracks[current.track];
      if (!t) return;
      if (current.frame >= t.n - 1) showFrame(0);
      var step = Math.max(1, Math.round(t.n / 600));  // a whole program in about 20 s
      playButton.textContent = 'Pause';
      playing = setInterval(function () {
        if (current.frame >= t.n - 1) { stop(); return; }
        showFrame(current.frame + step);
      }, 33);
    });
    slider.addEventListener('input', function () { stop(); showFrame(parseInt(slider.value, 10)); });
    trackSelect.addEventListener('change', function () { stop(); setTrack(parseInt(trackSelect.value, 10)); showFrame(0); });
    colourSelect.addEventListener('change', function () { setColour(colourSelect.value); render(); });
    var layers = { envelope: envelopeLayer, ruled: ruledLayer, path: pathLayer, part: partLayer, tool: toolLayer };
    Object.keys(layers).forEach(function (name) {
      var box = document.getElementById('fcv-show-' + name);  // none when the scene has no such layer
      if (box) box.addEventListener('change', function () { layers[name].visible = box.checked; render(); });
    });
    var setMachine = function (on) {
      machineMode = !!(on && machine);
      if (machineBox) machineBox.checked = machineMode;
      showFrame(current.frame);
    };
    if (machineBox) machineBox.addEventListener('change', function () { setMachine(machineBox.checked); });
    var fromHash = function () {
      var q = {};
      location.hash.replace(/^#/, '').split('&').forEach(function (kv) {
        var p = kv.split('=');
        if (p[0]) q[decodeURIComponent(p[0])] = decodeURIComponent(p[1] || '');
      });
      if (q.track !== undefined) setTrack(parseInt(q.track, 10) || 0);
      if (q.colour !== undefined) setColour(q.colour);
      if (q.hide !== undefined)
        q.hide.split(',').forEach(function (name) {
          if (!layers[name]) return;
          layers[name].visible = false;
          var box = document.getElementById('fcv-show-' + name);
          if (box) box.checked = false;
        });
      showFrame(q.pose !== undefined ? parseInt(q.pose, 10) || 0 : current.frame);
      if (q.machine !== undefined) setMachine(q.machine === '1');
      if (q.marker !== undefined && jumps[parseInt(q.marker, 10)]) jump(jumps[parseInt(q.marker, 10)]);
    };
    window.addEventListener('hashchange', fromHash);

    setColour('all');
    setTrack(0);
    resize();
    fromHash();
    requestAnimationFrame(function () {
      if (!/^error/.test(document.body.getAttribute('data-flankcam-viewer') || ''))
        document.body.setAttribute('data-flankcam-viewer', 'ready');
    });
  } catch (e) {
    fail(e && e.message ? e.message : String(e));
  }
})();
