; more than 250000 loop iterations @ 4:1
#1 = 0
o1 while [#1 GE 0]
o1 endwhile
