; M73 outside a subroutine @ 2:1
M73
