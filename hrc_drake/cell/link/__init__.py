"""The station and the controller in two processes: LCM messages (`lcm_struct`, `lcm_messages`)
on their channels (`channels`), the lockstep both sides follow (`lockstep`), its two halves
(`interface` the controller's, `station_server` the station's), the runs over it (`remote`) and
the check that both sides run the same scenario (`scenario_identity`)."""
