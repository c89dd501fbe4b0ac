// Simulation model of the ECP5 TRELLIS_FF flip-flop as springflat instantiates it (hdl/dsp.py's
// kept_register: the block RAMs' pin registers, register copies): CEMUX "1" (always enabled) or "CE"
// (loads when CE is high), REGSET "RESET", LSR either tied low or the domain's reset, a synchronous
// clear that wins over CE (SRMODE "LSR_OVER_CE", LSRMUX "LSR"); Q starts at 0. Any other use stops
// the simulation.
`timescale 1ns/1ps
module TRELLIS_FF (input CLK, LSR, CE, DI, M, output reg Q);
    parameter GSR = "ENABLED";
    parameter [127:0] CEMUX = "1";
    parameter CLKMUX = "CLK";
    parameter LSRMUX = "LSR";
    parameter SRMODE = "LSR_OVER_CE";
    parameter REGSET = "RESET";
    parameter [127:0] LSRMODE = "LSR";
    initial begin
        if ((CEMUX != "1" && CEMUX != "CE") || CLKMUX != "CLK" || REGSET != "RESET" || LSRMUX != "LSR"
            || SRMODE != "LSR_OVER_CE" || LSRMODE != "LSR") begin
            $display("TRELLIS_FF model: unsupported parameters");
            $finish;
        end
        Q = 1'b0;
    end
    always @(posedge CLK) begin
        if (LSR === 1'b1)
            Q <= 1'b0;
        else if (LSR === 1'b0 && (CEMUX == "1" || CE === 1'b1))
            Q <= DI;
        else if (LSR === 1'b0 && CE === 1'b0)
            Q <= Q;
        else
            Q <= 1'bx;  // an undefined reset or enable, as a register with them in the generic Verilog
    end
endmodule
