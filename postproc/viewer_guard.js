// Runs before three.js: any uncaught error or console.error of the page marks <body> with
// data-flankcam-viewer="error: ...", which the browser test and a reader can see.
(function () {
  'use strict';
  var fail = function (message) {
    var b = document.body;
    if (b && !/^error/.test(b.getAttribute('data-flankcam-viewer') || '')) b.setAttribute('data-flankcam-viewer', 'error: ' + message);
    var box = document.getElementById('fcv-readout');
    if (box) box.textContent = '3D view failed: ' + message;
  };
  window.flankcamViewerFail = fail;
  window.onerror = function (message, source, line) { fail(String(message) + (line ? ' (line ' + line + ')' : '')); };
  window.addEventListener('unhandledrejection', function (e) { fail('unhandled rejection: ' + String(e.reason)); });
  var error = console.error;
  console.error = function () {
    fail(Array.prototype.map.call(arguments, String).join(' '));
    return error.apply(console, arguments);
  };
  document.body.setAttribute('data-flankcam-viewer', 'loading');
})();
