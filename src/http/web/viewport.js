// What every three.js view on the page does with its box: a renderer, or why there is none; its
// size followed (a phone turned, a window resized: a view drawn once at the width it had
// overflowed when it changed); the page's background when dark mode is switched while it is open.
import * as THREE from 'three';

/** A WebGL renderer for `el` (emptied first), or `null` with the reason written in `el` where the
 *  browser gives no WebGL. */
export function webgl(el) {
  el.replaceChildren();
  try {
    return new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  } catch (e) {
    const msg = document.createElement('p');
    msg.className = 'error';
    msg.textContent = `No 3D view: this browser gives no WebGL (${e.message}).`;
    el.appendChild(msg);
    return null;
  }
}

/** Keeps `renderer` and `camera` fitted to `el` and coloured as its background, calling
 *  `render` after each change. Returns the function that stops it. */
export function followBox(el, renderer, camera, render) {
  const resized = new ResizeObserver(() => {
    const [cw, ch] = [el.clientWidth, el.clientHeight];
    if (!cw || !ch) return;
    renderer.setSize(cw, ch);
    camera.aspect = cw / ch;
    camera.updateProjectionMatrix();
    render();
  });
  resized.observe(el);
  const scheme = window.matchMedia('(prefers-color-scheme: dark)');
  const recolour = () => { renderer.setClearColor(new THREE.Color(getComputedStyle(el).backgroundColor || '#fff')); render(); };
  scheme.addEventListener('change', recolour);
  return () => {
    resized.disconnect();
    scheme.removeEventListener('change', recolour);
  };
}
