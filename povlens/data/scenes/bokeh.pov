// povlens bokeh scene: highlights far out of focus, to show the aperture's shape.
//
// Units: 1 scene unit = 1 metre.  The camera looks along +z.  Three small emissive
// spheres (radius 6 cm) stand 15 m away, a warm one on the axis and two cooler ones
// beside it; a dim card 0.5 m from the camera carries the focus.
//   povlens render bokeh.pov --lens dgauss.50mm --focus 0.5 --film-diagonal 10 \
//       --method mesh --samples 256 --aperture-blades 6 -o out/bokeh
// Each highlight's blur is then the stop's image: round, or the iris's polygon
// (benchmarks/aperture_bokeh.py makes docs/images/aperture-bokeh.png).
#version 3.7;

global_settings { assumed_gamma 1.0 }

camera {
  perspective
  location <0, 0, 0>
  look_at  <0, 0, 1>
  right    x*image_width/image_height
  angle    8
}

background { rgb 0 }

#declare Glow = finish { emission 12 diffuse 0 ambient 0 };
sphere { <0, 0, 15>, 0.06 pigment { rgb <1.0, 0.75, 0.4> } finish { Glow } }
sphere { <-0.75, 0.45, 15>, 0.06 pigment { rgb <0.45, 0.7, 1.0> } finish { Glow } }
sphere { < 0.7, -0.5, 15>, 0.06 pigment { rgb <0.6, 1.0, 0.6> } finish { Glow } }

// The card in focus: a thin grey frame at the bottom edge of the view.
box { <-0.05, -0.036, 0.5>, <0.05, -0.032, 0.501>
      pigment { rgb 0.05 } finish { emission 0.3 diffuse 0 ambient 0 } }
