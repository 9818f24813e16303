//! Types shared by the tendril host (training, IPC processes) and firmware
//! (inference, control step): message layouts, robot/tension limits and the
//! versioned `.tnet` weight format.
#![no_std]
#![deny(missing_docs)]
