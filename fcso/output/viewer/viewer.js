// fcso report: the interactive 3D view (three.js r111, OrbitControls, GLTFLoader, all inlined in the page).
// Reads the JSON in #fcso-3d-data; draws one view at a time; check boxes show and hide its groups.
(function () {
  "use strict";
  var data = JSON.parse(document.getElementById("fcso-3d-data").textContent);
  var canvas = document.getElementById("fcso-3d-canvas");
  var COLOURS = { part: 0x9a9aa6, fingers: 0x6f8fd0, pad: 0xe6731a, contact: 0xd62020 };
  var renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(0xf4f4f8);
  var scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x707080, 0.85));
  var sun = new THREE.DirectionalLight(0xffffff, 0.6);
  scene.add(sun);
  var camera = new THREE.PerspectiveCamera(35, canvas.width / canvas.height, 0.1, 1e5);
  camera.up.set(0, 0, 1);
  var controls = new THREE.OrbitControls(camera, canvas);
  var geometries = {};
  var shown = { part: true, fingers: true, pad: true, contact: true };
  var current = new THREE.Group();
  scene.add(current);

  function bytes(base64) {
    var text = atob(base64), out = new Uint8Array(text.length);
    for (var i = 0; i < text.length; i++) out[i] = text.charCodeAt(i);
    return out;
  }

  function draw() {
    sun.position.copy(camera.position);
    renderer.render(scene, camera);
  }

  function material(group) {
    // the pocket lies on the finger's own surface: drawn a little in front so it shows
    return new THREE.MeshStandardMaterial({
      color: COLOURS[group], metalness: 0.0, roughness: 0.8, side: THREE.DoubleSide, flatShading: true,
      polygonOffset: group === "pad", polygonOffsetFactor: -1, polygonOffsetUnits: -1
    });
  }

  function show(index) {
    scene.remove(current);
    current = new THREE.Group();
    data.views[index].items.forEach(function (item) {
      var object;
      if (item.points) {
        var geometry = new THREE.BufferGeometry();
        var values = new Float32Array(bytes(data.points[item.points]).buffer);
        geometry.setAttribute("position", new THREE.BufferAttribute(values, 3));
        object = new THREE.Points(geometry, new THREE.PointsMaterial({ color: COLOURS.contact, size: 2.5, sizeAttenuation: false }));
      } else {
        object = new THREE.Mesh(geometries[item.mesh], material(item.group));
      }
      if (item.matrix) {
        object.matrixAutoUpdate = false;
        object.matrix.fromArray(item.matrix);
      }
      object.userData.group = item.group;
      object.visible = shown[item.group];
      current.add(object);
    });
    scene.add(current);
    current.updateMatrixWorld(true);
    var box = new THREE.Box3().setFromObject(current);
    var centre = box.getCenter(new THREE.Vector3());
    var radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1);
    controls.target.copy(centre);
    camera.position.copy(centre).add(new THREE.Vector3(1.2, -1.6, 1.0).multiplyScalar(radius * 1.6));
    camera.near = radius / 100;
    camera.far = radius * 100;
    camera.updateProjectionMatrix();
    controls.update();
    draw();
  }

  function setUp() {
    var select = document.getElementById("fcso-3d-view");
    data.views.forEach(function (view, index) {
      var option = document.createElement("option");
      option.value = index;
      option.textContent = view.title;
      select.appendChild(option);
    });
    select.addEventListener("change", function () { show(Number(select.value)); });
    var boxes = document.getElementById("fcso-3d-groups");
    Object.keys(shown).forEach(function (group) {
      var label = document.createElement("label");
      var box = document.createElement("input");
      box.type = "checkbox";
      box.checked = true;
      box.addEventListener("change", function () {
        shown[group] = box.checked;
        current.children.forEach(function (object) { object.visible = shown[object.userData.group]; });
        draw();
      });
      label.appendChild(box);
      label.appendChild(document.createTextNode(" " + group + " "));
      boxes.appendChild(label);
    });
    controls.addEventListener("change", draw);
    show(0);
    canvas.setAttribute("data-ready", "true");
  }

  var keys = Object.keys(data.meshes), left = keys.length, loader = new THREE.GLTFLoader();
  keys.forEach(function (key) {
    loader.parse(bytes(data.meshes[key]).buffer, "", function (gltf) {
      // the GLB has no normals: the materials shade flat, face by face, as a part's edges are
      gltf.scene.traverse(function (node) { if (node.isMesh) geometries[key] = node.geometry; });
      if (--left === 0) setUp();
    }, function (error) { console.error("fcso 3D view: mesh " + key + ": " + error); });
  });
})();
