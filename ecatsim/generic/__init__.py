"""Generic slaves: a device that is data, from its ESI (ETG.2000) or the master's ENI
(ETG.2100), served by the same OD model, SDO server and PDO copy as the TMC8670."""
