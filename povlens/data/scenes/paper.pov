// povlens test scene after the 2012 paper: three coloured mirror balls
// receding in depth over a checker floor, seen by one ordinary camera.
//
// Units: 1 scene unit = 1 metre.  Camera 1.5 m above the floor.
// Ball centres are about 4.7, 7.1 and 12.3 m from the camera; the floor checker is
// 0.5 m.  Render: povray -D +Ipaper.pov +Opaper.png +W640 +H480
#version 3.7;

global_settings { assumed_gamma 1.0 max_trace_level 8 }

camera {
  perspective
  location <0, 1.5, -3>
  look_at  <0, 0.7, 5>
  right    x*image_width/image_height
  angle    45
}

light_source { <-4, 9, -6> rgb 1.0 }
light_source { <7, 5, -3> rgb 0.35 shadowless }

sky_sphere {
  pigment {
    gradient y
    color_map { [0.0 rgb <0.85, 0.90, 1.00>] [1.0 rgb <0.20, 0.40, 0.85>] }
  }
}

plane {
  y, 0
  pigment { checker rgb 0.85 rgb 0.06 scale 0.5 }
  finish { ambient 0.05 diffuse 0.8 reflection 0.05 }
}

#declare BallRadius = 0.5;
#declare Mirror = finish {
  ambient 0 diffuse 0.1 specular 0.9 roughness 0.002
  reflection { 0.8 metallic }
}

sphere { <-1.1, BallRadius, 1.5>,  BallRadius pigment { rgb <0.95, 0.20, 0.12> } finish { Mirror } }
sphere { < 0.4, BallRadius, 4>,  BallRadius pigment { rgb <0.20, 0.85, 0.25> } finish { Mirror } }
sphere { < 2.2, BallRadius, 9>,  BallRadius pigment { rgb <0.20, 0.35, 0.95> } finish { Mirror } }
