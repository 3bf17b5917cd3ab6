; duplicate O-word label o7 @ 5:1
o7 if [1]
G0 X1
o7 endif
o7 while [0]
o7 endwhile
