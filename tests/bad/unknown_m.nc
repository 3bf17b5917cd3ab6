; unknown M code M1.5 @ 2:1
M1.5
