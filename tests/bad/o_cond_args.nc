; if needs one [condition] @ 2:1
o1 if
o1 endif
