//! `bake-all` on a terminal: what stays on the screen once the progress display is gone. The
//! command runs on a pseudo-terminal and its output is replayed through a terminal emulator,
//! so cursor movements and line clears act as they would for a user.

use crate::{BAKE_ALL, MRES};
use std::io::Read;
use std::os::fd::{FromRawFd, OwnedFd};
use std::path::Path;
use std::process::{Command, Stdio};

const ROWS: u16 = 200;
const COLS: u16 = 240;

/// Runs `bin args` with stdout and stderr on a new pty of ROWS×COLS; returns the exit code and
/// the screen's text after the command ended.
fn run_on_terminal(bin: &str, args: &[&str]) -> (Option<i32>, String) {
    let (mut master, mut slave) = (0, 0);
    let size = libc::winsize { ws_row: ROWS, ws_col: COLS, ws_xpixel: 0, ws_ypixel: 0 };
    // SAFETY: openpty writes two descriptors into the given integers; the name and termios
    // arguments may be null.
    let rc = unsafe { libc::openpty(&mut master, &mut slave, std::ptr::null_mut(), std::ptr::null(), &size) };
    assert_eq!(rc, 0, "openpty: {}", std::io::Error::last_os_error());
    // SAFETY: both descriptors were just opened and are owned by nobody else.
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
    let mut child = {
        let mut command = Command::new(bin);
        command
            .args(args)
            .env("TERM", "xterm-256color")
            .env_remove("NO_COLOR")
            .stdin(Stdio::null())
            .stdout(Stdio::from(slave.try_clone().unwrap()))
            .stderr(Stdio::from(slave));
        command.spawn().expect("spawn")
        // The command, holding the parent's copies of the slave, is dropped here, so that
        // reading the master ends when the child exits.
    };
    let mut master = std::fs::File::from(master);
    let mut bytes = Vec::new();
    let mut buffer = [0u8; 4096];
    loop {
        match master.read(&mut buffer) {
            Ok(0) | Err(_) => break, // EIO once every slave descriptor is closed
            Ok(n) => bytes.extend_from_slice(&buffer[..n]),
        }
    }
    let status = child.wait().expect("wait");
    let mut parser = vt100::Parser::new(ROWS.try_into().unwrap(), COLS.try_into().unwrap(), 0);
    parser.process(&bytes);
    (status.code(), parser.screen().contents())
}

fn write_tree(dir: &Path, broken: usize) {
    std::fs::create_dir_all(dir).unwrap();
    let o = Command::new(MRES).args(["generate", "sphere", "24", "-o"]).arg(dir.join("ball.obj")).output().unwrap();
    assert!(o.status.success());
    for i in 0..broken {
        std::fs::write(dir.join(format!("broken{i:02}.obj")), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    }
}

#[test]
fn the_failure_summary_survives_the_progress_display() {
    let dir = tempfile::tempdir().unwrap();
    let assets = dir.path().join("assets");
    write_tree(&assets, 11);
    let out = dir.path().join("out");
    let (code, screen) =
        run_on_terminal(BAKE_ALL, &[assets.to_str().unwrap(), "-o", out.to_str().unwrap(), "--no-cache", "-j", "2"]);
    assert_eq!(code, Some(1), "{screen}");
    let summary = screen.lines().position(|l| l.contains("12 assets: 1 baked")).unwrap_or_else(|| panic!("{screen}"));
    let after: Vec<&str> = screen.lines().skip(summary + 1).collect();
    for i in 0..11 {
        let name = format!("broken{i:02}.obj");
        assert!(
            after.iter().any(|l| l.starts_with("failed: ") && l.contains(&name)),
            "no `failed:` line for {name} below the summary:\n{screen}"
        );
    }
}
