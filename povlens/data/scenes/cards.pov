// povlens depth-graded test scene: five checker cards at increasing depth.
//
// Units: 1 scene unit = 1 metre.  The camera is at the origin and looks along +z
// (31 degree horizontal field of view, as the 50 mm lenses on a 35 mm diagonal).  Card i stands at depth Z[i] (0.8, 1.3,
// 2.1, 3.4 and 5.5 m: even steps in dioptres, about 0.47 D apart), left to right,
// each scaled with its depth so that all look the same size with the same
// checker (six squares across), so the sharpness of each is comparable: which card
// is sharpest says where the focus is.  A grey wall 9 m away closes the view.
// Render: povray -D +Icards.pov +Ocards.png +W640 +H480
#version 3.7;

global_settings { assumed_gamma 1.0 }

camera {
  perspective
  location <0, 0, 0>
  look_at  <0, 0, 1>
  right    x*image_width/image_height
  angle    31
}

light_source { <0, 0, -0.2> rgb 1.0 }   // at the eye: the cards' shadows hide behind them
light_source { <-2, 3, 0> rgb 0.4 shadowless }
background { rgb 0.01 }

// The wall behind.
plane { -z, -9 pigment { rgb 0.15 } finish { ambient 0 diffuse 0.8 } }

#declare Z = array[5] { 0.8, 1.3, 2.1, 3.4, 5.5 };
#declare HalfTan = tan(radians(15.5));
#for (I, 0, 4)
  #declare U = (I - 2) * 0.36;                  // the card's centre, fraction of the half width
  #declare S = Z[I] * HalfTan;                  // half the frame width at the card's depth
  #declare W = 0.13 * S;                        // half the card's width
  box {
    <-W, -W, 0>, <W, W, 0.01>
    pigment { checker rgb 0.9 rgb 0.04 scale W / 3 translate <0, 0, W / 6> }
    finish { ambient 0 diffuse 0.9 }
    translate <U * S, 0, Z[I]>
  }
#end
