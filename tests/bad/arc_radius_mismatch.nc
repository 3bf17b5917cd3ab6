; differs from radius to start @ 2:4
G3 X10 Y0 I4 J0 F100
