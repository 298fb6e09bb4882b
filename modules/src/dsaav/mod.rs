//! DSAAV services over the IComms medium of `seabus-medium` (`dsaav+…://`), layered as in the
//! paper: [`rpc`] (reliable, unreliable and broadcast calls) carries the core services.

pub mod rpc;
