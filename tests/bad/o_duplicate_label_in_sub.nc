; duplicate O-word label o101 @ 7:3
G21 G90 G17
o100 sub
  o101 repeat [1]
    G1 X[#1] F100
  o101 endrepeat
  o101 repeat [1]
    G1 X0
  o101 endrepeat
o100 endsub
o100 call [5]
M2
