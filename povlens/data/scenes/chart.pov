// povlens test chart: bokeh, focus and distortion.
//
// Units: 1 scene unit = 1 metre.  The camera stands 1.5 m above the floor and
// looks horizontally along +z (50 degree horizontal field of view).
//   * small emissive highlights (radius 1.5 cm, emission 40) at 1.5, 3, 6 and
//     12 m -> bokeh shape and size versus depth;
//   * a checker/resolution chart (7.5 cm squares, Siemens star) tilted 35
//     degrees about the vertical, centred 3 m away -> focus falls off across it;
//   * a white wall 8 m away with straight black lines every 0.5 m reaching
//     the frame edges -> distortion.
// Render: povray -D +Ichart.pov +Ochart.png +W640 +H480
#version 3.7;

global_settings { assumed_gamma 1.0 }

camera {
  perspective
  location <0, 1.5, 0>
  look_at  <0, 1.5, 1>
  right    x*image_width/image_height
  angle    50
}

light_source { <-3, 6, -2> rgb 1.0 }
light_source { < 4, 3, -1> rgb 0.3 shadowless }
background { rgb 0.01 }

// Floor.
plane { y, 0 pigment { rgb 0.25 } finish { ambient 0.02 diffuse 0.7 } }

// Wall at z = 8 m with a grid of straight lines (2 cm wide, every 0.5 m).
#declare WallZ = 8;
#declare LineW = 0.02;
union {
  box { <-6, 0, WallZ>, <6, 6, WallZ + 0.1> pigment { rgb 0.8 } }
  #for (I, -12, 12)
    box { <I*0.5 - LineW/2, 0, WallZ - 0.001>, <I*0.5 + LineW/2, 6, WallZ> pigment { rgb 0.02 } }
  #end
  #for (J, 1, 11)
    box { <-6, J*0.5 - LineW/2, WallZ - 0.001>, <6, J*0.5 + LineW/2, WallZ> pigment { rgb 0.02 } }
  #end
  finish { ambient 0.05 diffuse 0.8 }
}

// Tilted checker chart (1.2 m x 0.9 m) with a Siemens star, 3 m away.
union {
  box { <-0.6, -0.45, 0>, <0.6, 0.45, 0.01>
    pigment { checker rgb 0.95 rgb 0.03 scale 0.075 translate <0, 0, 0.005> }
  }
  disc { <0.3, 0.15, -0.001>, -z, 0.14 pigment { rgb 0.95 } }
  disc { <0.3, 0.15, -0.002>, -z, 0.13
    pigment { radial frequency 24 color_map { [0.5 rgb 0.03] [0.5 rgb 0.95] } rotate -90*x translate <0.3, 0.15, 0> }
  }
  finish { ambient 0.05 diffuse 0.8 }
  rotate 35*y
  translate <-0.45, 1.45, 3>
}

// Emissive point highlights at several depths.
#declare Highlight = sphere { 0, 0.015
  pigment { rgb 1 }
  finish { ambient 0 diffuse 0 emission 40 }
  no_shadow
}
object { Highlight translate < 0.30, 1.30, 1.5> }
object { Highlight translate < 0.75, 1.75, 3.0> }
object { Highlight translate < 0.95, 1.20, 3.0> }
object { Highlight translate < 1.60, 2.10, 6.0> }
object { Highlight translate <-1.40, 0.90, 6.0> }
object { Highlight translate < 2.90, 2.60, 12.0> }
object { Highlight translate <-2.60, 0.70, 12.0> }
